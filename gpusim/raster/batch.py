"""The rasterizer's input: triangles in homogeneous clip space, in submission order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class TriangleBatch:
    """``clip`` (T,3,4) float64 clip-space vertices, ``rgba`` (T,3,4) float64 straight
    colour/alpha per vertex, ``opaque`` (T,) bool, ``prim`` (T,) uint32 primitive index
    (defaults to 0..T-1: the submission order)."""

    clip: np.ndarray
    rgba: np.ndarray
    opaque: np.ndarray
    prim: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.clip = np.ascontiguousarray(self.clip, dtype=np.float64)
        self.rgba = np.ascontiguousarray(self.rgba, dtype=np.float64)
        self.opaque = np.asarray(self.opaque, dtype=bool)
        t = self.clip.shape[0]
        if self.clip.shape != (t, 3, 4) or self.rgba.shape != (t, 3, 4) or self.opaque.shape != (t,):
            raise ValueError(f"inconsistent triangle batch shapes {self.clip.shape}, "
                             f"{self.rgba.shape}, {self.opaque.shape}")
        if self.prim is None:
            self.prim = np.arange(t, dtype=np.uint32)
        self.prim = np.asarray(self.prim, dtype=np.uint32)

    def __len__(self) -> int:
        return self.clip.shape[0]

    @classmethod
    def concat(cls, batches: list["TriangleBatch"]) -> "TriangleBatch":
        """Join batches in order, renumbering primitives 0..T-1."""
        if not batches:
            return cls(np.zeros((0, 3, 4)), np.zeros((0, 3, 4)), np.zeros(0, bool))
        return cls(np.concatenate([b.clip for b in batches]),
                   np.concatenate([b.rgba for b in batches]),
                   np.concatenate([b.opaque for b in batches]))

    @classmethod
    def from_window(cls, xy: np.ndarray, width: int, height: int, z: np.ndarray | None = None,
                    rgba: np.ndarray | None = None, opaque: np.ndarray | None = None) -> "TriangleBatch":
        """Triangles given directly in window pixel coordinates (T,3,2), with w = 1.

        ``z`` (T,3) is window depth in [0, 1] (default 0.5). Handy for tests and
        for feeding an identical orthographic input to OpenGL.
        """
        xy = np.asarray(xy, dtype=np.float64)
        t = xy.shape[0]
        clip = np.ones((t, 3, 4))
        clip[..., 0] = xy[..., 0] / width * 2.0 - 1.0
        clip[..., 1] = xy[..., 1] / height * 2.0 - 1.0
        clip[..., 2] = (np.full((t, 3), 0.5) if z is None else np.asarray(z)) * 2.0 - 1.0
        if rgba is None:
            rgba = np.broadcast_to([1.0, 1.0, 1.0, 0.5], (t, 3, 4))
        return cls(clip, rgba, np.zeros(t, bool) if opaque is None else opaque)
