"""The scene's fragment shader in a scheme's plan: ALU work at the head of each shading pass's threads.

Every geometry pass of fragment threads runs the scene's material program
(gpusim.shaders) on each fragment it shades before the scheme's own work: the
pixel shader of the hardware pipeline (helper lanes of partial quads run it
too: they fill the same warps), or FreePipe's software rasterizer, which
shades each fragment in its triangle loop. What a pass needs is its
``Pass.shading``: the whole program, the alpha alone, or nothing for a
depth-only pass. A pass's shaded fragments are the threads that issue its
operations. The work is a ``compute`` group put first in program order, so
each fragment shades before it reads or writes anything; the plan's access
counts are unchanged.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from gpusim.opplan import OpGroup, OpPlan, ThreadRange
from gpusim.shaders import FragmentShader


def _pass_threads(g: OpGroup, wanted: list[bool]):
    """(pass, threads) for each wanted pass ``g`` reaches: a ThreadRange where every thread of a range takes
    part, else the thread ids (unsorted, possibly repeated)."""
    count = g.count
    if g.seq_pass is not None:
        for at, p in enumerate(g.seq_pass[:int(count.max())].tolist()):
            if wanted[p]:
                if isinstance(g.thread, ThreadRange) and int(count.min()) > at:
                    yield p, g.thread
                else:
                    yield p, g.thread_ids()[count > at]
        return
    if g.pass_fn is not None:
        i, seq = g.expand_ops()
        pp = np.broadcast_to(np.asarray(g.pass_fn(i, seq), np.int64), i.shape)
        ids = g.thread_ids()
        for p in np.unique(pp).tolist():
            if wanted[p]:
                yield p, ids[i[pp == p]]
        return
    if np.isscalar(g.pass_index):
        if wanted[int(g.pass_index)]:
            yield int(g.pass_index), g.thread
        return
    pi = np.asarray(g.pass_index)
    ids = g.thread_ids()
    for p in np.unique(pi).tolist():
        if wanted[p]:
            yield p, ids[pi == p]


def shade_fragments(plan: OpPlan, shader: FragmentShader) -> None:
    """Put ``shader``'s work first in each shading pass of ``plan`` (in place): one compute group per pass,
    or one across the passes whose threads are all of a range (depth peeling's peels), so the plan still grows
    with the threads plus the passes."""
    wanted = [p.shades and shader.instructions(p.shading) > 0 for p in plan.passes]
    if not any(wanted):
        return
    ranges: dict[int, int] = {}
    parts: dict[int, list[np.ndarray]] = defaultdict(list)
    for g in plan.groups:
        for p, threads in _pass_threads(g, wanted):
            if isinstance(threads, ThreadRange):
                ranges[p] = max(ranges.get(p, 0), len(threads))
            else:
                parts[p].append(np.asarray(threads, np.int64))
    before = len(plan.groups)
    whole: dict[tuple[int, int], list[int]] = defaultdict(list)     # (range, instructions) -> its passes
    for p in sorted(set(ranges) | set(parts)):
        inst = shader.instructions(plan.passes[p].shading)
        n = ranges.get(p, 0)
        rest = [t[t >= n] for t in parts.get(p, [])]
        if n and not any(len(t) for t in rest):
            whole[(n, inst)].append(p)
            continue
        threads = np.unique(np.concatenate([np.arange(n, dtype=np.int64)] + rest))
        plan.compute(p, threads, inst, dep=False)
    for (n, inst), passes in whole.items():
        plan.compute(passes[0], n, inst, dep=False, count=len(passes), seq_pass=np.asarray(passes, np.int64))
    added = plan.groups[before:]
    del plan.groups[before:]
    plan.groups[:0] = added
