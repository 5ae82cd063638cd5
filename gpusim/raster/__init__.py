"""Rasterization: clip-space triangles to a :class:`~gpusim.trace.FragmentTrace`."""

from gpusim.raster.batch import TriangleBatch
from gpusim.raster.rasterizer import SUBPIXEL_BITS, rasterize

__all__ = ["SUBPIXEL_BITS", "TriangleBatch", "rasterize"]
