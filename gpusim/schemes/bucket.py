"""Bucket depth peeling and adaptive bucket depth peeling (Liu, Huang, Liu, Wu: "Efficient depth peeling via
bucket sort", HPG 2009; seed 000 Table 3's BDP, BDP2 and ADP).

Both capture the layers of a pixel into a *bucket array*: ``BUCKETS`` = 32 buckets of one 32-bit depth each,
8 RGBA32F render targets (MRTs) of 4 channels. A first pass (``bounds``) MAX-blends (-z, z) into
``depth_range`` (RG32F) to find each pixel's depth range [near, far]: with ``bounds = "box"`` (the paper's,
the default) it draws the scene's bounding box, so the range is the scene's at every pixel and the capture is
the method's single geometry pass; with ``bounds = "geometry"`` it is a geometry pass of the whole scene, each
pixel its own range (fewer collisions, one geometry pass more). In a capture pass each fragment loads
its pixel's range, computes its bucket, and writes its depth to that bucket's channel and the empty value to
the 31 others; MAX blending merges the 8 targets, so a bucket keeps the farthest depth routed to it. Two
fragments in one bucket collide: the nearer is lost (``bucket_collisions``, the ``dropped_fragments``; the
image shows the loss). A full-screen ``composite`` pass reads the buckets in order, which is depth order.

``bucket-depth-peeling`` divides [near, far] uniformly: the bucket of depth z is
min(floor(32 (z - near) / (far - near)), 31) in float32 (near goes to bucket 0, far to bucket 31; a pixel of
one distinct depth puts everything in bucket 0). With ``passes = 2`` (BDP2, the paper's multi-pass
approach) the range is divided into 64 uniform buckets, the nearer half of them captured by a first capture
pass and the farther half by a second, each into a bucket array of its own, and the composite reads both
(Table 3's 64 MB against BDP's 32 MB: two arrays of 32 MB at 512x512). A fragment outside a pass's half
still loads the range and computes its bucket, then is discarded.

``adaptive-bucket-depth-peeling`` (ADP) adds a ``histogram`` geometry pass between: [near, far] is divided
into ``histogram_bins`` uniform bins kept as one occupancy bit each (logical-OR blending into RGBA32UI
targets of 128 bins: blending can set a bit, not count). The capture pass reads the whole histogram and
equalises the buckets over the occupied bins: the r-th of a pixel's O occupied bins (nearest first) takes
bucket r when O <= 32, else floor(32 r / O), so each bucket gets as many occupied bins as any other. A
collision then needs two fragments in one bin (``bin_collisions``) or more than 32 occupied bins
(``merged_pixels``).

What the paper leaves open, read here (docs/schemes.md):

* the buckets hold depths only (seed 000 Table 3 renders translucency from the thickness between layers, and
  its 32 MB is the depth channels alone); the image composites each kept depth's own fragment's colour
  (float32), and of equal depths routed to one bucket the first submitted;
* the buckets are cleared to a value below every depth, so a depth of 0 is stored like any other;
* the bounding box is the scene's screen-aligned one (traces carry fragments, not the model's vertices): its
  front face at the least depth of any fragment, its back face at the greatest, over the rectangle of screen
  the fragments cover; the ``bounds`` pass draws its 12 triangles, a front and a back fragment at each pixel of
  that rectangle, a full-screen pass's cost over the rectangle (no scene geometry);
* every fragment of a capture pass writes all 8 targets (the ROP blends each), as an MRT draw does.

ALU work beyond each operation's own (gpusim.schemes.common.alu): a fragment's bucket or bin
(``BUCKET_INDEX``), its 32 output channels in a capture pass and one per histogram word in the histogram pass
(``CHANNEL_SELECT``); ADP's capture counts the occupied bins below its own over every histogram word
(``POPCOUNT_WORD``) and equalises (``EQUALISE``); the composite tests each bucket (``BUCKET_SCAN``) and
composites the kept ones (``COMPOSITE``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.metrics.composite import run_starts
from gpusim.opplan import OpPlan, Pass
from gpusim.schemes.base import Scheme, composite_stored, register
from gpusim.schemes.common.alu import (BUCKET_INDEX, BUCKET_SCAN, CHANNEL_SELECT, COMPOSITE, EQUALISE,
                                       POPCOUNT_WORD)
from gpusim.schemes.common.arrays import lex_order
from gpusim.schemes.common.groups import PixelGroups, distinct_rank_in_runs
from gpusim.schemes.common.storage import DEPTH_BYTES
from gpusim.schemes.result import CapturedLists, SchemeResult, Stat, Structure

BUCKETS = 32          # buckets per bucket array: 8 MRTs x 4 channels
CHANNELS = 4          # 32-bit channels per render-target texel
TEXEL_BYTES = 16      # one RGBA32F (or RGBA32UI) texel
RANGE_BYTES = 8       # RG32F (-near, far)
BINS_PER_TARGET = CHANNELS * 32     # histogram bins per RGBA32UI target (one bit each)


def depth_range(trace, g: PixelGroups) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's nearest and farthest depth (float32; 0 where it has no fragment): the bounds pass."""
    near = np.zeros(trace.pixel_count, np.float32)
    far = np.zeros(trace.pixel_count, np.float32)
    if len(trace):
        order = g.by_depth
        ps = g.pix[order]
        start = run_starts(ps)
        last = np.r_[start[1:], len(ps)] - 1
        near[ps[start]] = trace.z[order[start]]
        far[ps[last]] = trace.z[order[last]]
    return near, far


def box_range(trace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scene's screen-aligned bounding box: (near, far) of every pixel (float32: the least and greatest
    depth of any fragment inside the rectangle of screen the fragments cover, 0 outside) and the rectangle's
    pixels, which the ``bounds`` pass draws."""
    near = np.zeros(trace.pixel_count, np.float32)
    far = np.zeros(trace.pixel_count, np.float32)
    if not len(trace):
        return near, far, np.zeros(0, np.int64)
    xs = np.arange(int(trace.x.min()), int(trace.x.max()) + 1, dtype=np.int64)
    ys = np.arange(int(trace.y.min()), int(trace.y.max()) + 1, dtype=np.int64)
    box = (ys[:, None] * trace.width + xs[None, :]).ravel()
    near[box], far[box] = np.float32(trace.z.min()), np.float32(trace.z.max())
    return near, far, box


def bucket_of(z: np.ndarray, near: np.ndarray, far: np.ndarray, count: int) -> np.ndarray:
    """min(floor(count (z - near) / (far - near)), count - 1) in float32 (0 where far = near): the uniform bucket
    (or bin) of each depth in its pixel's range. Monotone in z, so buckets ascend with depth."""
    span = far - near
    t = np.zeros(len(z), np.float32)
    np.divide(z - near, span, out=t, where=span > 0)
    return np.minimum((t * np.float32(count)).astype(np.int64), count - 1)


def one_per_bucket(pix: np.ndarray, bucket: np.ndarray, key: np.ndarray) -> np.ndarray:
    """What MAX blending leaves: per (pixel, bucket) the farthest fragment (of equal depths the first
    submitted), grouped by pixel, buckets ascending (depth order)."""
    order = lex_order(pix, bucket, np.uint32(0xFFFFFFFF) - key)
    ps, bs = pix[order], bucket[order]
    first = np.ones(len(order), bool)
    first[1:] = (ps[1:] != ps[:-1]) | (bs[1:] != bs[:-1])
    return order[first]


def _targets(buckets: int) -> int:
    return buckets // CHANNELS


class _Ranges:
    """Each fragment's depth range and the ``bounds`` pass that finds it, as ``bounds`` chooses."""

    def __init__(self, bounds: str, trace, g: PixelGroups):
        if bounds == "box":
            near, far, self.box = box_range(trace)
        else:
            (near, far), self.box = depth_range(trace, g), None
        self.near, self.far = near[g.pix], far[g.pix]

    def used(self, g: PixelGroups) -> int:
        """Pixels the range is written at: the box's, or each covered pixel."""
        return g.covered if self.box is None else len(self.box)

    @property
    def geometry(self) -> int:
        """Geometry passes of the scene the bounds pass makes."""
        return int(self.box is None)

    def bounds_pass(self) -> Pass:
        return Pass("bounds", "geometry", "fragment", shading="none") if self.box is None else Pass("bounds", "fullscreen", "pixel")

    def add(self, plan: OpPlan, n: int, pix: np.ndarray, P: int, planes: dict[str, int]) -> None:
        """Pass 0 clears the range and each structure's ``planes`` screen-sized target planes; pass 1 (bounds)
        MAX-blends every fragment's (-z, z), or the box's front and back faces at each pixel it covers."""
        plan.add(0, "store", "depth_range", P, 1, lambda i, s: i * RANGE_BYTES, RANGE_BYTES)
        for name, count in planes.items():
            plan.add(0, "store", name, P * count, 1, lambda i, s: i * TEXEL_BYTES, TEXEL_BYTES)
        if self.box is None:
            plan.add(1, "blend", "depth_range", n, 1, lambda i, s: pix[i] * RANGE_BYTES, RANGE_BYTES)
        else:
            box = self.box
            plan.add(1, "blend", "depth_range", box, 2, lambda i, s: box[i] * RANGE_BYTES, RANGE_BYTES)


def _route(plan: OpPlan, pass_index: int, n: int, pix: np.ndarray, P: int, instructions, writers,
           structure: str, first_plane: int, planes: int, reads: tuple[str, int] | None = None) -> None:
    """A capture or histogram pass: every fragment loads its range (and ``reads``: a structure's planes),
    computes (``instructions`` per fragment), and the ``writers`` (an array, or n for all) blend ``planes``
    target planes of ``structure`` from ``first_plane`` on."""
    plan.add(pass_index, "load", "depth_range", n, 1, lambda i, s: pix[i] * RANGE_BYTES, RANGE_BYTES)
    if reads is not None:
        plan.add(pass_index, "load", reads[0], n, reads[1], lambda i, s: (s * P + pix[i]) * TEXEL_BYTES,
                 TEXEL_BYTES)
    plan.compute(pass_index, n, instructions)
    wp = pix if isinstance(writers, int) else pix[writers]
    plan.add(pass_index, "blend", structure, writers, planes,
             lambda i, s: ((first_plane + s) * P + wp[i]) * TEXEL_BYTES, TEXEL_BYTES, dep=True)


def _composite(plan: OpPlan, pass_index: int, P: int, buckets: int, kept_n: np.ndarray) -> None:
    """The full-screen pass: every pixel reads its bucket arrays, tests each bucket, composites the kept."""
    plan.add(pass_index, "load", "buckets", P, _targets(buckets), lambda i, s: (s * P + i) * TEXEL_BYTES,
             TEXEL_BYTES)
    plan.compute(pass_index, P, buckets * BUCKET_SCAN + kept_n * COMPOSITE)


def _result(scheme, trace, g: PixelGroups, kept: np.ndarray, buckets: int, plan: OpPlan, ranges: _Ranges,
            scene_passes: int, structures: list[Structure], stats: dict[str, Stat]) -> SchemeResult:
    """The result; ``scene_passes``: the geometry passes besides the bounds pass."""
    n, P, pix = len(trace), trace.pixel_count, g.pix
    kept_n = np.bincount(pix[kept], minlength=P)
    _composite(plan, len(plan.passes) - 1, P, buckets, kept_n)
    lost = n - len(kept)
    structures = [Structure("depth_range", RANGE_BYTES, P, ranges.used(g), "RG32F (-near, far) of each pixel"),
                  *structures,
                  Structure("buckets", DEPTH_BYTES, P * buckets, len(kept),
                            f"{buckets} buckets of a 32-bit depth per pixel ({_targets(buckets)} RGBA32F targets)")]
    stats = {"bucket_collisions": Stat(int(lost), "fragments", "fragments lost to a bucket that kept a farther "
                                       "fragment (or an equal depth submitted earlier): MAX blending keeps one"),
             **stats}
    return SchemeResult(scheme.name, scheme.params(), composite_stored(trace, pix, kept, "rgba32f"), n, g.covered,
                        structures, plan, geometry_passes=ranges.geometry + scene_passes,
                        dropped_fragments=int(lost),
                        overflowed_pixels=int(np.count_nonzero(g.count > kept_n)),
                        lists=CapturedLists(pix[kept], kept), stats=stats)


@dataclass(frozen=True)
class _Bucketed(Scheme):
    """What the bucket schemes share: where the depth range comes from."""

    bounds: Literal["box", "geometry"] = param(
        "box", doc="the bounds pass that finds each pixel's depth range: 'box' draws the scene's bounding box "
        "(the paper's: the range is the scene's at every pixel, no scene geometry), 'geometry' draws the scene "
        "(each pixel's own range: fewer collisions, one geometry pass more)")


@register("bucket-depth-peeling")
@dataclass(frozen=True)
class BucketDepthPeeling(_Bucketed):
    summary = "bucket depth peeling: 32 uniform depth buckets per pixel over 8 MRTs, MAX blending (Liu et al. 2009)"

    passes: int = param(1, unit="passes", doc="capture passes: the range is split into passes x 32 uniform "
                        "buckets, each pass capturing its 32 into a bucket array of its own (2: BDP2)", min=1, max=4)

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix, c = len(trace), trace.pixel_count, g.pix, self.passes
        buckets = BUCKETS * c
        ranges = _Ranges(self.bounds, trace, g)
        bucket = bucket_of(trace.z, ranges.near, ranges.far, buckets)
        passes = [Pass("clear", "clear", "entry"), ranges.bounds_pass()]
        passes += [Pass(f"capture {i}", "geometry", "fragment", shading="none") for i in range(c)]   # depths only
        passes.append(Pass("composite", "fullscreen", "pixel"))
        plan = OpPlan(passes, ["depth_range", "buckets"])
        ranges.add(plan, n, pix, P, {"buckets": _targets(buckets)})
        capture = bucket // BUCKETS
        for i in range(c):
            mine = capture == i
            _route(plan, 2 + i, n, pix, P, BUCKET_INDEX + mine * (BUCKETS * CHANNEL_SELECT),
                   n if c == 1 else np.flatnonzero(mine), "buckets", i * _targets(BUCKETS), _targets(BUCKETS))
        kept = one_per_bucket(pix, bucket, g.key)
        return _result(self, trace, g, kept, buckets, plan, ranges, c, [], {})


@register("adaptive-bucket-depth-peeling")
@dataclass(frozen=True)
class AdaptiveBucketDepthPeeling(_Bucketed):
    summary = "adaptive bucket depth peeling: 32 buckets equalised over a depth-occupancy histogram (Liu et al. 2009)"

    histogram_bins: int = param(512, unit="bins/pixel", doc="uniform bins of the occupancy histogram over the "
                                "pixel's depth range, one bit each (a multiple of 128: RGBA32UI targets)",
                                min=128, max=1024)

    def __post_init__(self) -> None:
        if self.histogram_bins % BINS_PER_TARGET:
            raise ValueError(f"histogram_bins {self.histogram_bins} is not a multiple of {BINS_PER_TARGET} (the "
                             "bins of one RGBA32UI target)")

    def simulate(self, trace) -> SchemeResult:
        g = PixelGroups(trace)
        n, P, pix, H = len(trace), trace.pixel_count, g.pix, self.histogram_bins
        words, targets = H // 32, H // BINS_PER_TARGET
        ranges = _Ranges(self.bounds, trace, g)
        bin_ = bucket_of(trace.z, ranges.near, ranges.far, H)
        # each fragment's bin's rank among its pixel's occupied bins, and their number
        order = lex_order(pix, bin_)
        ps = pix[order]
        rank = np.empty(n, np.int64)
        rank[order] = ranked = distinct_rank_in_runs(ps, bin_[order])
        occupied = np.zeros(P, np.int64)
        if n:
            last = np.r_[run_starts(ps)[1:], n] - 1
            occupied[ps[last]] = ranked[last] + 1
        bucket = np.where(occupied[pix] <= BUCKETS, rank, rank * BUCKETS // np.maximum(occupied[pix], 1))

        passes = [Pass("clear", "clear", "entry"), ranges.bounds_pass(),
                  Pass("histogram", "geometry", "fragment", shading="none"),
                  Pass("capture", "geometry", "fragment", shading="none"),
                  Pass("composite", "fullscreen", "pixel")]
        plan = OpPlan(passes, ["depth_range", "histogram", "buckets"])
        ranges.add(plan, n, pix, P, {"histogram": targets, "buckets": _targets(BUCKETS)})
        _route(plan, 2, n, pix, P, BUCKET_INDEX + words * CHANNEL_SELECT, n, "histogram", 0, targets)
        _route(plan, 3, n, pix, P, BUCKET_INDEX + words * POPCOUNT_WORD + EQUALISE + BUCKETS * CHANNEL_SELECT, n,
               "buckets", 0, _targets(BUCKETS), reads=("histogram", targets))
        kept = one_per_bucket(pix, bucket, g.key)
        word = bin_[order] // 32                 # the histogram words holding an occupied bin: (pixel, word) runs
        used_words = int(np.count_nonzero(np.r_[True, (ps[1:] != ps[:-1]) | (word[1:] != word[:-1])])) if n else 0
        hist = Structure("histogram", 4, P * words, used_words,
                         f"{H} occupancy bits per pixel ({targets} RGBA32UI targets), 32 bins per word")
        merged = int(np.count_nonzero(occupied > BUCKETS))
        stats = {"bin_collisions": Stat(int(n - occupied.sum()), "fragments",
                                        "fragments sharing a histogram bin with another fragment of their pixel"),
                 "merged_pixels": Stat(merged, "pixels", f"pixels with more occupied bins than the {BUCKETS} buckets "
                                       "(bins share buckets)"),
                 "occupied_bins": Stat(int(occupied.max(initial=0)), "bins",
                                       "largest number of occupied histogram bins of a pixel")}
        return _result(self, trace, g, kept, BUCKETS, plan, ranges, 2, [hist], stats)
