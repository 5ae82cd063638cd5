"""Per-pixel linked lists (Yang et al. 2010).

Structures: ``head`` (one 32-bit node index per pixel, cleared to NIL),
``nodes`` (a pool of ``pool_nodes_per_pixel`` x W x H nodes of colour, depth
and a 32-bit next index) and ``counter`` (one global 32-bit allocation counter).

``capture``: each fragment ``atomic_inc`` s the global counter (every fragment
of the frame hits this one address) to allocate node i; if i is inside the
pool it stores its colour and depth in the node, ``atomic_exch`` s the pixel's
head with i and stores the returned old head as the node's next index. A
fragment whose i is past the pool's end is dropped (``pool_overflow``). The
functional model allocates nodes in submission order.

``resolve`` (one thread per pixel): load the head, then walk the list (one
``load`` per node), most recent fragment first, into a local array of at most
``resolve_max`` entries (0: unlimited; a full array drops the older rest),
sort it (stable insertion sort by default: equal depths end in *walk* order,
i.e. the later-submitted fragment in front, unlike the reference) and
composite front to back. The walk is run for real over the pointer arrays, so
a list that loses or repeats a node would show in the captured lists.

ALU work beyond each operation's own (gpusim.schemes.common.alu): the resolve
sorts the m nodes it loaded (``sort_compares(m)`` x ``compare_exchange`` of
depth + colour), then unpacks (``UNPACK_RGBA8`` for rgba8 nodes: a raw buffer)
and composites (``COMPOSITE``) each one; m is each pixel's real walk length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_stored, register
from gpusim.schemes.common.alu import COMPOSITE, UNPACK_RGBA8, compare_exchange, sort_compares
from gpusim.schemes.common.arrays import lex_order
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.sorting import sort_runs
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES, POINTER_BYTES, ColourFormat
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

NIL = -1


def walk_lists(head: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Follow every list from ``head`` (pixel -> node or NIL): (pixel, step, node) of each visit."""
    start_pixels = np.flatnonzero(head != NIL)
    cur = head[start_pixels]
    pixels, steps, nodes = [], [], []
    step = 0
    alive = start_pixels
    while len(cur):
        pixels.append(alive)
        steps.append(np.full(len(cur), step))
        nodes.append(cur)
        cur = nxt[cur]
        keep = cur != NIL
        cur, alive = cur[keep], alive[keep]
        step += 1
    if not pixels:
        return (np.zeros(0, np.int64),) * 3
    return np.concatenate(pixels), np.concatenate(steps), np.concatenate(nodes)


@register("linked-list")
@dataclass(frozen=True)
class LinkedList(Scheme):
    summary = "per-pixel linked lists with a global atomic node counter (Yang et al. 2010)"

    pool_nodes_per_pixel: float = param(8.0, unit="nodes/pixel", doc="node pool size, per screen pixel", gt=0.0)
    colour_format: ColourFormat = param("rgba8", doc="node colour format")
    resolve_max: int = param(0, unit="fragments", doc="resolve's local array size (0: unlimited)", min=0)
    sort: Literal["insertion", "bitonic"] = param("insertion", doc="resolve sort")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        pool = int(math.ceil(self.pool_nodes_per_pixel * P))
        node_bytes = COLOUR_BYTES[self.colour_format] + DEPTH_BYTES + POINTER_BYTES
        payload = node_bytes - POINTER_BYTES
        allocated = np.arange(n) < pool                    # node i = i-th fragment (submission order)
        alloc_idx = np.flatnonzero(allocated)
        # pointer structure: each allocated node links to the previous allocated node of its pixel
        head = np.full(P, NIL, np.int64)
        nxt = np.full(len(alloc_idx), NIL, np.int64)
        if len(alloc_idx):
            by_pix = g.by_arrival[allocated[g.by_arrival]]     # allocated nodes by pixel, in order
            pix_sorted = pix[by_pix]
            same = np.r_[False, pix_sorted[1:] == pix_sorted[:-1]]
            nxt[by_pix[same]] = by_pix[np.flatnonzero(same) - 1]
            last = np.r_[~same[1:], True]
            head[pix_sorted[last]] = by_pix[last]
        w_pix, w_step, w_node = walk_lists(head, nxt)
        visit = lex_order(w_pix, w_step)
        w_pix, w_step, w_node = w_pix[visit], w_step[visit], w_node[visit]
        walked = np.bincount(w_pix, minlength=P)
        limit = self.resolve_max or np.iinfo(np.int64).max
        keep = w_step < limit

        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment"),
                  Pass("resolve", "fullscreen", "pixel")]
        plan = OpPlan(passes, ["head", "nodes", "counter"])
        pixels, frags = P, n
        plan.add(0, "store", "head", pixels, 1, lambda i, s: i * POINTER_BYTES, POINTER_BYTES)
        plan.add(0, "store", "counter", np.zeros(1, np.int64), 1, lambda i, s: i * 0, POINTER_BYTES)
        plan.add(1, "atomic_inc", "counter", frags, 1, lambda i, s: i * 0, POINTER_BYTES)
        plan.add(1, "store", "nodes", alloc_idx, 1, lambda i, s: alloc_idx[i] * node_bytes, payload, dep=True)
        plan.add(1, "atomic_exch", "head", alloc_idx, 1, lambda i, s: pix[alloc_idx[i]] * POINTER_BYTES,
                 POINTER_BYTES, dep=True)
        plan.add(1, "store", "nodes", alloc_idx, 1, lambda i, s: alloc_idx[i] * node_bytes + payload,
                 POINTER_BYTES, dep=True)
        plan.add(2, "load", "head", pixels, 1, lambda i, s: i * POINTER_BYTES, POINTER_BYTES)
        loads = np.minimum(walked, limit)
        visited_nodes = w_node[keep]
        first_visit = np.r_[0, np.cumsum(loads)[:-1]]
        plan.add(2, "load", "nodes", pixels, loads,
                 lambda i, s: visited_nodes[first_visit[i] + s] * node_bytes, node_bytes, dep=True)
        # in registers: sort the walked nodes, then unpack and composite them front to back
        exchange = compare_exchange(COLOUR_BYTES[self.colour_format])
        unpack = UNPACK_RGBA8 if self.colour_format == "rgba8" else 0
        plan.compute(2, pixels, sort_compares(loads, self.sort) * exchange + loads * (COMPOSITE + unpack))

        loaded, loaded_pix = w_node[keep], w_pix[keep]     # walk order: most recent first
        perm, compares = sort_runs(loaded_pix, g.key[loaded], self.sort)
        order = loaded[perm]                               # runs stay in place: loaded_pix is pix[order]
        overflow = n - len(alloc_idx)
        struct = [Structure("head", POINTER_BYTES, P, g.covered, "head node index per pixel"),
                  Structure("nodes", node_bytes, pool, len(alloc_idx),
                            f"node: {self.colour_format} colour, depth, next index"),
                  Structure("counter", POINTER_BYTES, 1, 1 if n else 0, "global node allocation counter")]
        lost = g.count > np.bincount(loaded_pix, minlength=P)
        image = composite_stored(trace, pix, order, self.colour_format, loaded_pix)
        return SchemeResult(self.name, self.params(), image, n,
                            g.covered, struct, plan, geometry_passes=1,
                            dropped_fragments=int(n - len(order)), overflowed_pixels=int(lost.sum()),
                            lists=CapturedLists(loaded_pix, order),
                            stats={"pool_overflow": Stat(int(overflow), "fragments", "fragments past the pool's end"),
                                   "walk_visits": Stat(int(len(w_node)), "nodes", "nodes the resolve walk reached"),
                                   "sort_compares": Stat(compares, "compares", f"{self.sort} sort compares")},
                            extras={"walk": CapturedLists(w_pix, w_node)})
