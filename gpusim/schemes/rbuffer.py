"""The R-buffer (Wittenbrink 2001, as in seed 003 section 2.5.1 and Figures 2-3, 2-4).

Structures (Table 4-2): ``r_buffer``, a FIFO of N_f x S_f bytes (N_f: the
transparent fragments stored after early z; S_f: a fragment with its x, y, z
and RGBA, since a FIFO entry does not know its pixel); ``second_z_buffer``
(W x H depths); ``state_memory`` (3 bits per pixel; the thesis gives its size
but not its accesses, so the model issues none).

Passes:

1. ``clear``: the second z-buffer is set to the nearest depth.
2. ``capture`` (phase 1, gpusim.schemes.common.early_z): opaque fragments go to the
   z-buffer and frame buffer; a transparent fragment that passes early z is
   appended to the FIFO and raises its pixel's second-z to the furthest
   stored depth (one ROP depth test).
3. ``recirculate p`` (phases 2 and 3, Figure 2-4), p = 1, 2, ...: every
   fragment still in the FIFO is read and compared with its pixel's second-z
   (seed 003 section 4.3.2: pass p reads every fragment still in the buffer and
   the second z-buffer as often). One whose depth equals it is blended into the
   frame buffer back to front (Eq. 1) and leaves; the others are written back
   to the FIFO's tail and raise the next pass's second-z. Pass 1 also drops
   the fragments a later opaque fragment occludes (phase 2); if the furthest
   stored fragment was one of them, that pixel blends nothing in pass 1.

Equal depths match the second-z together and are blended in the same pass in
FIFO (arrival) order, so the earlier fragment ends up *behind* the later one,
the opposite of the reference's order (``tie_blends`` counts them). With
distinct depths a pixel with i fragments is read i(i+1)/2 times in total.
The FIFO is circular: the k-th write goes to entry k mod N_f.

ALU work beyond each operation's own (gpusim.schemes.common.alu): every read
of a recirculation pass compares the fragment with its pixel's second z and
branches, to the blend or back to the FIFO (``RECIRCULATE_TEST``); the blend is
the ROP's. No sort: recirculation is the sort.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gpusim.config import param
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, register
from gpusim.schemes.common.alu import RECIRCULATE_TEST
from gpusim.schemes.common.arrays import lex_sorted, reversed_runs
from gpusim.schemes.common.early_z import early_z, pipeline_buffers, pipeline_structures, storage_bytes
from gpusim.schemes.common.fold import fold
from gpusim.schemes.common.groups import PixelGroups, distinct_rank_in_runs
from gpusim.schemes.common.weights import unorm_rounder
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure


def far_rank(pix: np.ndarray, key: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For fragments ``idx``: how many distinct depths of their pixel (among ``idx``) lie behind them; and
    the order of ``idx`` grouped by pixel, farthest first (equal depths in ``idx`` order)."""
    key = key[idx]
    order, pix_sorted = lex_sorted(pix[idx], ~key)
    rank = np.empty(len(idx), np.int64)
    rank[order] = distinct_rank_in_runs(pix_sorted, key[order])
    return rank, order


def fifo_sequence(pos: np.ndarray, pass_no: np.ndarray, members: np.ndarray) -> np.ndarray:
    """Global FIFO sequence number of every (fragment, pass) read.

    ``pos`` is the fragment's position in the first pass's FIFO, ``pass_no``
    the 1-based pass; the pairs must be all reads of each pass given.
    ``members[p - 1]`` is how many fragments pass p reads.
    """
    offset = np.r_[0, np.cumsum(members)]
    key = pass_no.astype(np.int64) * (int(pos.max(initial=0)) + 1) + pos
    order = np.argsort(key, kind="stable")
    rank = np.empty(len(key), np.int64)
    sorted_pass = pass_no[order]
    group_start = np.searchsorted(sorted_pass, sorted_pass, side="left")
    rank[order] = np.arange(len(key)) - group_start
    return offset[pass_no - 1] + rank


@register("r-buffer")
@dataclass(frozen=True)
class RBuffer(Scheme):
    summary = "R-buffer: recirculating FIFO of transparent fragments + second z-buffer (Wittenbrink 2001)"

    fragment_bytes: int = param(16, unit="bytes", doc="S_f: x, y, z (32-bit each) + RGBA of a FIFO entry", min=1)
    depth_bytes: int = param(4, unit="bytes", doc="one second-z-buffer entry (as the z-buffer's)", min=1, max=8)
    state_bits: int = param(3, unit="bits/pixel", doc="pixel state memory per pixel", min=0, max=64)
    colour_bits: int = param(8, unit="bits/channel", doc="colour component bit width (FIFO and frame buffer)",
                             min=1, max=16)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix = len(trace), trace.pixel_count, g.pix
        SF, ZB, bits = self.fragment_bytes, self.depth_bytes, self.colour_bits
        fb_bytes = math.ceil(4 * bits / 8)
        rnd = unorm_rounder(bits)

        passes = [Pass("clear", "clear", "entry"), Pass("capture", "geometry", "fragment")]
        plan = OpPlan(passes, pipeline_structures(trace, ["r_buffer", "second_z_buffer", "state_memory"]))
        plan.add(0, "store", "second_z_buffer", P, 1, lambda i, s: i * ZB, ZB)
        ez = early_z(trace, g, plan, 1, fb_bytes, rnd)
        stored = np.flatnonzero(ez.stored)                      # FIFO order = submission order
        n_f = len(stored)
        pos = np.arange(n_f)
        occluded = ~ez.visible[stored]
        vis_idx = stored[~occluded]
        shift = np.zeros(P, np.int64)
        shift[pix[stored[occluded]]] = 1
        removal = np.ones(n_f, np.int64)                         # 1-based pass in which it leaves
        rank, back_to_front = far_rank(pix, g.key, vis_idx)
        removal[~occluded] = shift[pix[vis_idx]] + rank + 1
        n_pass = int(removal.max(initial=0))
        members = np.bincount(removal, minlength=n_pass + 1)[::-1].cumsum()[::-1][1:]   # reads per pass
        plan.passes.extend(Pass(f"recirculate {p}", "buffer", "fragment") for p in range(1, n_pass + 1))

        slot = lambda seq: (seq % max(n_f, 1)) * SF  # noqa: E731
        plan.add(1, "store", "r_buffer", stored, 1, lambda i, s: slot(pos[i]), SF, dep=True)
        plan.add(1, "depth_test", "second_z_buffer", stored, 1, lambda i, s: pix[stored[i]] * ZB, ZB, dep=True)
        read_pass = 2 + np.arange(n_pass)        # pass index of read s + 1 (recirculation passes start at 2)
        plan.add(2, "load", "r_buffer", stored, removal,
                 lambda i, s: slot(fifo_sequence(pos[i], s + 1, members)), SF, seq_pass=read_pass)
        plan.add(2, "depth_test", "second_z_buffer", stored, removal, lambda i, s: pix[stored[i]] * ZB, ZB,
                 dep=True, seq_pass=read_pass)
        # every read: at the second z, blend and leave; else write back
        plan.compute(2, stored, RECIRCULATE_TEST, count=removal, seq_pass=read_pass)
        vis_pos = np.flatnonzero(~occluded)
        plan.add(2, "blend", "framebuffer", stored[vis_pos], 1, lambda i, s: pix[stored[vis_pos[i]]] * fb_bytes,
                 fb_bytes, dep=True, pass_fn=lambda i, s: 1 + removal[vis_pos[i]])
        plan.add(2, "store", "r_buffer", stored, removal - 1,
                 lambda i, s: slot(fifo_sequence(pos[i], s + 2, members)), SF, dep=True, seq_pass=read_pass)

        # image: back to front, equal depths in FIFO order, rounded after every blend (Eq. 1)
        blend_order = vis_idx[back_to_front]
        rgba = rnd(np.take(trace.rgba, blend_order, axis=0))     # in blending order

        def step(state, i):
            rows = np.take(rgba, i, axis=0)
            a = rows[:, 3:4]
            return rnd(a * rows[:, :3] + (1 - a) * state)

        image = fold(pix, blend_order, ez.opaque_rgb.copy(), step).reshape(trace.height, trace.width, 3)
        same = np.r_[False, (pix[blend_order][1:] == pix[blend_order][:-1])
                     & (g.key[blend_order][1:] == g.key[blend_order][:-1])]
        blended = np.bincount(pix[vis_idx], minlength=P) > 0
        struct = [
            *pipeline_buffers(P, fb_bytes, bits, ez, blended),
            Structure("r_buffer", SF, n_f, n_f, "FIFO of stored transparent fragments (N_f x S_f)"),
            Structure("second_z_buffer", ZB, P, int(np.count_nonzero(np.bincount(pix[stored], minlength=P))),
                      "furthest remaining transparent depth per pixel"),
            Structure("state_memory", 1, math.ceil(self.state_bits * P / 8), 0,
                      f"{self.state_bits} bits of pixel state per pixel (no accesses modelled)"),
        ]
        storage = storage_bytes(struct)
        front_to_back = blend_order[reversed_runs(pix[blend_order])]
        stats = {
            "recirculation_passes": Stat(n_pass, "passes", "FIFO passes until the R-buffer is empty"),
            "storage_system_bytes": Stat(storage, "bytes", "Table 4-2 total: R-buffer + second z-buffer + "
                                                           "state memory"),
            "stored_fragments": Stat(n_f, "fragments", "N_f: transparent fragments written to the FIFO"),
            **ez.stats("dropped in pass 1"),
            "tie_blends": Stat(int(np.count_nonzero(same)), "fragments",
                               "fragments blended in the same pass as an equal-depth one (FIFO order)"),
        }
        return SchemeResult(
            self.name, self.params(), image, n, g.covered, struct, plan, geometry_passes=1,
            dropped_fragments=0, overflowed_pixels=0, lists=CapturedLists(pix[front_to_back], front_to_back),
            stats=stats, extras={"read_per_pixel": np.bincount(pix[stored], minlength=P)})
