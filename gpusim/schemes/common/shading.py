"""The scene's fragment shader in a scheme's plan: ALU work at the head of each shading pass's threads.

Every geometry pass of fragment threads runs the scene's material program
(gpusim.shaders) on each fragment it shades before the scheme's own work: the
pixel shader of the graphics pipeline (helper lanes of partial quads run it
too: they fill the same warps), or FreePipe's software rasterizer, which
shades each fragment in its triangle loop. What a pass needs is its
``Pass.shading``: the whole program, the alpha alone, or nothing for a
depth-only pass. A pass's shaded fragments are the threads that issue its
operations (its depth-tested fragments included: the shader runs before the
ROP's depth test, as a late-z pipeline does). The work is a ``compute`` group
put first in program order, so each fragment shades before it reads or writes
anything, or, in a pass whose program opens with the k-buffer's dispatch
scoreboard (proposal 1, which holds a fragment's whole program), right after
its ``scoreboard`` operation. The plan's access counts are unchanged.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from gpusim.opplan import OpGroup, OpPlan, ThreadRange
from gpusim.schemes.common.arrays import split_by
from gpusim.shaders import FragmentShader


def _pass_threads(g: OpGroup, wanted: list[bool]):
    """(pass, threads) for each wanted pass ``g`` reaches: a ThreadRange where every thread of a range takes
    part, else the ids of the threads with work there (unsorted, possibly repeated)."""
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
        ids = g.thread_ids()[i]
        for p, at in split_by(np.broadcast_to(np.asarray(g.pass_fn(i, seq), np.int64), i.shape)):
            if wanted[p]:
                yield p, ids[at]
        return
    working = count > 0
    if np.isscalar(g.pass_index):
        p = int(g.pass_index)
        if wanted[p]:
            yield p, g.thread if isinstance(g.thread, ThreadRange) and bool(working.all()) else g.thread_ids()[working]
        return
    ids = g.thread_ids()[working]
    for p, at in split_by(np.asarray(g.pass_index, np.int64)[working]):
        if wanted[p]:
            yield p, ids[at]


def shade_fragments(plan: OpPlan, shader: FragmentShader) -> None:
    """Put ``shader``'s work first in each shading pass of ``plan`` (in place; after the dispatch scoreboard
    where a pass has one): one compute group per pass, or one across the passes whose threads are all of a range
    (depth peeling's peels), so the plan still grows with the threads plus the passes."""
    wanted = [p.shades and shader.instructions(p.shading) > 0 for p in plan.passes]
    if not any(wanted):
        return
    ranges: dict[int, int] = {}
    parts: dict[int, list[np.ndarray]] = defaultdict(list)
    first: dict[int, int] = {}           # each pass's first group in program order
    for index, g in enumerate(plan.groups):
        for p, threads in _pass_threads(g, wanted):
            first.setdefault(p, index)
            if isinstance(threads, ThreadRange):
                ranges[p] = max(ranges.get(p, 0), len(threads))
            else:
                parts[p].append(np.asarray(threads, np.int64))
    # a pass whose program opens with a ``scoreboard`` (a dispatch scoreboard, the k-buffer's proposal 1: the
    # fragment is held from dispatch) shades right after it; a later one (MLAB's rasterizer-ordered view, an
    # interlock around the read-modify-write only) leaves the shader first
    position = {p: i + 1 for p, i in first.items() if plan.groups[i].op == "scoreboard"}
    inserts: list[tuple[int, OpGroup]] = []
    whole: dict[tuple[int, int, int], list[int]] = defaultdict(list)    # (range, instructions, position): passes

    def add(at: int, *args, **kwargs) -> None:
        before = len(plan.groups)
        plan.compute(*args, dep=False, **kwargs)
        inserts.extend((at, g) for g in plan.groups[before:])
        del plan.groups[before:]

    for p in sorted(set(ranges) | set(parts)):
        inst = shader.instructions(plan.passes[p].shading)
        n = ranges.get(p, 0)
        rest = [t[t >= n] for t in parts.get(p, [])]
        if n and not any(len(t) for t in rest):
            whole[(n, inst, position.get(p, 0))].append(p)
            continue
        add(position.get(p, 0), p, np.unique(np.concatenate([np.arange(n, dtype=np.int64)] + rest)), inst)
    for (n, inst, at), passes in whole.items():
        add(at, passes[0], n, inst, count=len(passes), seq_pass=np.asarray(passes, np.int64))
    # from the back, so earlier positions hold; at one position the last made first, so they keep their order
    for _, (at, g) in sorted(enumerate(inserts), key=lambda item: (-item[1][0], -item[0])):
        plan.groups.insert(at, g)
