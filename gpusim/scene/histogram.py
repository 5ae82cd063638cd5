"""Frames synthesised from per-pixel fragment histograms (seed 003 Table 4-1).

A histogram scene file has ``kind = "histogram"`` at its top level and gives,
instead of geometry, how many pixels carry 1, 2, 3, ... transparent fragments
(``transparent_per_pixel``) and how many fragments the frame has in all
(``fragments``). The trace it makes has exactly those counts:

* transparent pixels are chosen at random (seeded) over the screen; a pixel
  with i transparent fragments gets i distinct depths in [0, 0.5);
* the opaque fragments (``fragments`` minus the transparent ones) lie behind
  every transparent one, in [0.5, 1): one per pixel while they last, the rest
  on random pixels, so early z discards no transparent fragment and the stored
  histogram is the table's;
* colours are uniform in [0, ``rgb_max``] and alphas in ``alpha_range``
  (Table 4-1 gives no colours; see ``rgb_max`` in the bundled files);
* submission order is a seeded random permutation of all fragments.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim import __version__
from gpusim.config import param, to_dict
from gpusim.scene.model import Screen
from gpusim.trace import FragmentTrace


@dataclass(frozen=True, kw_only=True)
class HistogramScene:
    """A frame given by its per-pixel transparent-fragment histogram."""

    kind: Literal["histogram"] = param("histogram", doc="marks a histogram scene file")
    name: str = param("histogram", doc="scene name, recorded in the trace")
    description: str = param("", doc="one line about the scene")
    source: str = param("", doc="where the numbers come from")
    screen: Screen = param(Screen())
    transparent_per_pixel: tuple[int, ...] = param(
        doc="N_1, N_2, ...: pixels with exactly 1, 2, ... transparent fragments")
    fragments: int = param(0, unit="fragments", doc="all fragments of the frame (opaque = this - transparent); "
                                                    "0 = one opaque fragment per pixel", min=0)
    rgb_max: float = param(1.0, unit="[0,1]", doc="colour channels are uniform in [0, rgb_max]", min=0.0, max=1.0)
    alpha_range: tuple[float, float] = param((0.1, 0.9), unit="[0,1]", doc="alphas are uniform in this range")
    seed: int = param(0, doc="random seed (placement, depths, colours, order)")

    def __post_init__(self) -> None:
        if any(c < 0 for c in self.transparent_per_pixel):
            raise ValueError("transparent_per_pixel counts must be >= 0")
        lo, hi = self.alpha_range
        if not 0.0 <= lo <= hi <= 1.0:
            raise ValueError("alpha_range must satisfy 0 <= low <= high <= 1")
        pixels = self.screen.width * self.screen.height
        if sum(self.transparent_per_pixel) > pixels:
            raise ValueError(f"transparent_per_pixel names {sum(self.transparent_per_pixel):,} pixels but the "
                             f"screen has {pixels:,}")
        if self.fragments and self.fragments < self.transparent_fragments:
            raise ValueError(f"fragments ({self.fragments:,}) is fewer than the transparent fragments "
                             f"({self.transparent_fragments:,})")

    @property
    def transparent_fragments(self) -> int:
        return sum((i + 1) * c for i, c in enumerate(self.transparent_per_pixel))


def histogram_trace(scene: HistogramScene) -> FragmentTrace:
    """The trace of a histogram scene (deterministic for its seed)."""
    rng = np.random.default_rng(scene.seed)
    W, H = scene.screen.width, scene.screen.height
    P = W * H
    hist = np.asarray(scene.transparent_per_pixel, np.int64)
    layers = np.repeat(np.arange(1, len(hist) + 1), hist)             # per transparent pixel
    t_pixels = rng.choice(P, size=len(layers), replace=False)
    t_pix = np.repeat(t_pixels, layers)
    starts = np.cumsum(layers) - layers
    rank = np.arange(len(t_pix)) - np.repeat(starts, layers)         # 0..i-1 inside a pixel
    depth_slot = rank[_shuffle_within(rng, layers)]                   # a random permutation per pixel
    i_of = np.repeat(layers, layers)
    t_z = (depth_slot + rng.uniform(0.1, 0.9, len(t_pix))) / i_of * 0.5
    n_opaque = (scene.fragments or (P + scene.transparent_fragments)) - scene.transparent_fragments
    o_pix = np.r_[np.arange(min(n_opaque, P)), rng.integers(0, P, max(n_opaque - P, 0))]
    o_z = rng.uniform(0.5, 1.0, len(o_pix))
    pix = np.r_[t_pix, o_pix]
    z = np.r_[t_z, o_z].astype(np.float32)
    n = len(pix)
    rgba = np.empty((n, 4), np.float32)
    rgba[:, :3] = rng.uniform(0.0, scene.rgb_max, (n, 3))
    rgba[:, 3] = rng.uniform(*scene.alpha_range, n)
    opaque = np.r_[np.zeros(len(t_pix), bool), np.ones(len(o_pix), bool)]
    rgba[opaque, 3] = 1.0
    order = rng.permutation(n)
    meta = {"scene": scene.name, "generator": "gpusim trace (histogram)", "gpusim_version": __version__,
            "background": list(scene.screen.background), "scene_config": to_dict(scene)}
    pix, z, rgba, opaque = pix[order], z[order], np.take(rgba, order, axis=0), opaque[order]
    return FragmentTrace((pix % W).astype(np.uint16), (pix // W).astype(np.uint16), z, rgba,
                         np.arange(n, dtype=np.uint32), opaque, W, H, meta)


def _shuffle_within(rng, lengths: np.ndarray) -> np.ndarray:
    """A permutation of 0..sum(lengths)-1 that shuffles inside each consecutive run."""
    run = np.repeat(np.arange(len(lengths)), lengths)
    return np.lexsort((rng.random(len(run)), run))
