"""Phases 1 and 2 of the transparent-storage pipelines of seed 003 (Figures 2-4, 2-5, 3-1).

Shared by ``tfss``, ``r-buffer`` and ``weight-factor``. Fragments arrive in
submission order:

* an **opaque** fragment is depth-tested against the z-buffer (LESS); if it
  passes it writes the z-buffer and its colour into the frame buffer. Opaque
  fragments never enter the transparent storage.
* a **transparent** fragment is tested against the z-buffer *as it is when the
  fragment arrives* (early z, no write): behind the nearest opaque fragment so
  far it is discarded (``culled_at_arrival``); otherwise it is stored.
* phase 2: a stored fragment that a *later* opaque fragment occludes is
  discarded when the storage is read (``occluded_after_store``): it cost
  storage and reads but is never blended.

A frame without opaque fragments builds no z-buffer and tests nothing.
The z-buffer and frame buffer are the standard pipeline's; the thesis's
Table 4-2 counts neither, so the schemes report them as structures of their
own (``z_buffer``, ``framebuffer``) and give the thesis's total separately.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.metrics.composite import run_starts
from gpusim.opplan import OpPlan
from gpusim.schemes.common.arrays import put_rows
from gpusim.schemes.common.groups import PixelGroups
from gpusim.schemes.common.storage import DEPTH_BYTES
from gpusim.schemes.result import Stat, Structure

_FAR = np.uint64(1) << np.uint64(32)     # "no opaque fragment yet": behind every key


@dataclass(eq=False)
class EarlyZ:
    """Outcome of phase 1: which transparent fragments are stored and which stay visible."""

    stored: np.ndarray          # bool per fragment: transparent and passed early z at arrival
    visible: np.ndarray         # bool per fragment: stored and in front of the final nearest opaque
    opaque_rgb: np.ndarray      # (pixel_count, 3) float32: nearest opaque colour, or the background
    has_opaque: np.ndarray      # bool per pixel: at least one opaque fragment
    uses_z: bool                # the frame has opaque fragments (else no z-buffer is built or tested)
    culled_at_arrival: int
    occluded_after_store: int
    #: ``stored``, ``visible`` and the depth keys in the arrival order ``PixelGroups.by_arrival``
    stored_by_arrival: np.ndarray | None = None
    visible_by_arrival: np.ndarray | None = None
    key_by_arrival: np.ndarray | None = None

    def stats(self, occluded_fate: str = "read, not blended") -> dict[str, Stat]:
        """The two discard counts every scheme on this pipeline reports."""
        return {"culled_at_arrival": Stat(self.culled_at_arrival, "fragments", "transparent fragments behind "
                                          "the nearest opaque one so far (not stored)"),
                "occluded_after_store": Stat(self.occluded_after_store, "fragments",
                                             f"stored fragments a later opaque fragment hid ({occluded_fate})")}


def early_z(trace, g: PixelGroups, plan: OpPlan, pass_index: int, framebuffer_bytes: int,
            colour_round) -> EarlyZ:
    """Run phase 1 (adding its z-buffer and frame-buffer operations to ``plan``) and phase 2's test."""
    opaque, pix = trace.opaque, g.pix
    # in arrival order (grouped by pixel): what each pixel sees fragment after fragment
    order, pix_sorted = g.by_arrival, g.pix_by_arrival
    key, is_opaque = g.key[order], opaque[order]
    okey = np.where(is_opaque, key, np.uint32(0xFFFFFFFF))   # above every depth key
    # nearest opaque depth submitted *before* each fragment at its pixel (none before a pixel's first: far)
    start = run_starts(pix_sorted)
    through = _running_min_through(pix_sorted, okey)
    passes = np.empty(g.n, bool)
    np.less(key[1:], through[:-1], out=passes[1:])
    passes[start] = True
    stored_sorted = ~is_opaque & passes
    # nearest opaque depth of the whole frame: the running minimum through each pixel's last fragment
    last = np.r_[start[1:], g.n] - 1 if g.n else order
    final = np.full(trace.pixel_count, _FAR)
    final[pix_sorted[last]] = through[last]
    visible_sorted = stored_sorted & (key < final[pix_sorted])
    # one scatter back to submission order: stored, visible and written (opaque passing LESS) as bits 0, 1, 2
    flags_sorted = stored_sorted.view(np.uint8) | (visible_sorted.view(np.uint8) << np.uint8(1))
    flags_sorted |= (is_opaque & passes).view(np.uint8) << np.uint8(2)
    flags = np.empty(g.n, np.uint8)
    flags[order] = flags_sorted
    stored, visible, written = ((flags & np.uint8(bit)) != 0 for bit in (1, 2, 4))
    writes = np.flatnonzero(written)
    opaque_rgb = np.empty((trace.pixel_count, 3), np.float32)
    opaque_rgb[:] = colour_round(trace.background.astype(np.float32))
    if len(writes):
        # the last write at a pixel is its nearest opaque fragment (first submitted among equals)
        at = np.flatnonzero(is_opaque & passes)
        winners = order[at[np.r_[pix_sorted[at][1:] != pix_sorted[at][:-1], True]]]
        put_rows(opaque_rgb, pix[winners], colour_round(np.take(trace.rgba, winners, axis=0)[:, :3]))
    uses_z = bool(opaque.any())
    if uses_z:   # every fragment tests the z-buffer
        plan.add(pass_index, "depth_test", "z_buffer", g.n, 1, lambda i, s: pix[i] * DEPTH_BYTES, DEPTH_BYTES)
    plan.add(pass_index, "store", "framebuffer", writes, 1,
             lambda i, s: pix[writes[i]] * framebuffer_bytes, framebuffer_bytes, dep=True)
    # a pixel's running minimum stays at 0xFFFFFFFF (above every key) when none of its fragments is opaque
    return EarlyZ(stored, visible, opaque_rgb, final < np.uint64(0xFFFFFFFF), uses_z,
                  culled_at_arrival=int(np.count_nonzero(~is_opaque & ~passes)),
                  occluded_after_store=int(np.count_nonzero(stored_sorted & ~visible_sorted)),
                  stored_by_arrival=stored_sorted, visible_by_arrival=visible_sorted, key_by_arrival=key)


def _running_min_through(pix_sorted: np.ndarray, key: np.ndarray) -> np.ndarray:
    """For grouped runs of uint32 keys: the least key of each run up to and including each entry (one running
    maximum of ``pixel << 32 | ~key``: a larger pixel id starts afresh)."""
    word = pix_sorted.astype(np.uint64)
    word <<= np.uint64(32)
    word |= np.invert(key).astype(np.uint64)
    np.maximum.accumulate(word, out=word)
    return np.invert(word.astype(np.uint32))


PIPELINE = ("z_buffer", "framebuffer")


def pipeline_structures(trace, names: list[str]) -> list[str]:
    """``names`` after the pipeline buffers this frame needs (no z-buffer without opaque fragments)."""
    return (["z_buffer"] if trace.opaque.any() else []) + ["framebuffer"] + names


def storage_bytes(structures: list[Structure]) -> int:
    """Bytes of the transparent storage system alone (what Table 4-2 counts)."""
    return sum(s.allocated_bytes for s in structures if s.name not in PIPELINE)


def resolve_writes(plan: OpPlan, pass_index: int, pix: np.ndarray, visible: np.ndarray, pixel_count: int,
                   framebuffer_bytes: int, blended: np.ndarray | None = None) -> np.ndarray:
    """Read-pass frame-buffer load (opaque colour) and store (result) per pixel that blends; blended per pixel
    (``blended``: the visible fragments per pixel, when the caller has counted them)."""
    if blended is None:
        blended = np.bincount(pix[visible], minlength=pixel_count)
    bpix = np.flatnonzero(blended)
    plan.add(pass_index, "load", "framebuffer", bpix, 1, lambda i, s: bpix[i] * framebuffer_bytes,
             framebuffer_bytes)
    plan.add(pass_index, "store", "framebuffer", bpix, 1, lambda i, s: bpix[i] * framebuffer_bytes,
             framebuffer_bytes, dep=True)
    return blended


def pipeline_buffers(pixel_count: int, framebuffer_bytes: int, colour_bits: int, ez: EarlyZ,
                     blended: np.ndarray) -> list[Structure]:
    """The standard pipeline's z-buffer and frame buffer (not part of the thesis's Table 4-2 totals)."""
    has_opaque = ez.has_opaque
    z = [Structure("z_buffer", DEPTH_BYTES, pixel_count, int(np.count_nonzero(has_opaque)),
                   "32-bit depth per pixel (standard pipeline)")] if ez.uses_z else []
    return z + [Structure("framebuffer", framebuffer_bytes, pixel_count, int(np.count_nonzero(has_opaque | blended)),
                      f"{4 * colour_bits}-bit RGBA per pixel (standard pipeline)")]
