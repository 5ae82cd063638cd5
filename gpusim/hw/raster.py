"""Primitive processing: the geometry front end of the graphics pipeline, and software rasterization.

A geometry pass of the graphics pipeline gets its fragments from the front
end, a pipeline of stages each with its own throughput:

* vertex fetch: ``vertices_per_triangle`` shaded vertices per triangle (the
  post-transform cache's average miss rate), ``vertex_bytes`` each, read at
  the DRAM channels' bandwidth; or, with ``vertex_source = "host"`` (OpenGL
  client-side vertex arrays, or a mesh larger than device memory), the draw's
  index and vertex arrays over the host bus at ``host_bytes_per_cycle``: three
  32-bit indices per triangle and ``MESH_VERTICES_PER_TRIANGLE`` vertices of
  ``vertex_bytes`` (the vertex array of a closed mesh, sent once per draw);
* vertex shading: ``vertex_instructions`` per shaded vertex, on
  ``vertex_lanes`` dedicated vertex lanes (G71 has separate vertex shaders), or
  on all the SMs' lanes when ``vertex_lanes`` is 0 (a unified GPU);
* primitive assembly and setup: ``triangles_per_cycle``;
* rasterization in 2x2 quads: ``quads_per_cycle``. A quad that a triangle
  covers only in part still fills four shader lanes (helper lanes), so a
  pass's pixel-shader warps hold ``4 x quads`` lanes, not one per fragment.

Stages overlap (buffers between them), so triangle ``i`` leaves the front end
once every stage has done the work of triangles ``0..i``: the largest of the
stages' cumulative times. A warp starts once its last fragment's triangle is
out, and a pass lasts at least as long as its whole front end. Every pass of a
multi-pass scheme submits the scene again and pays it again; a batch of the
k-buffer's heuristic pays only its own triangles. Contention of vertex work
with fragment work for the same SM lanes and DRAM channels is not modelled:
each stage is timed at its own peak rate.

A software rasterizer (the ``triangle`` thread mapping, FreePipe) runs in the
threads instead, one thread per submitted triangle (triangles that cover no
pixel included): each thread loads its triangle's indices (``INDEX_BYTES``,
FreePipe's int4 texel), then its three vertices (``3 x vertex_bytes``, laid
out per triangle: the texture cache's re-use of shared vertices is not
modelled), runs ``setup_instructions`` (transform, clipping, culling and edge
setup), then tests every pixel of its triangle's bounding box
(``pixel_instructions`` each) and issues its fragments' operations
(gpusim.hw.lower). A warp lasts as long as its longest thread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import FP, Unit, occupancy_stats, register_unit
from gpusim.metrics.composite import run_starts


INDEX_BYTES = 16        # a software rasterizer's triangle indices: one int4 texel
HOST_INDEX_BYTES = 4    # a vertex index sent from host memory (GL_UNSIGNED_INT)
#: vertices per triangle of a closed triangle mesh (Euler: V - E + F = 2 - 2g with E = 3F / 2, so V = F / 2 +
#: 2 - 2g; the Stanford Dragon has 437,645 vertices for 871,414 triangles, Lucy 14,027,872 for 28,055,742)
MESH_VERTICES_PER_TRIANGLE = 0.5


@dataclass(frozen=True)
class RasterConfig:
    """The geometry front end (vertex fetch and shading, setup, quad rasterization) and the software
    rasterizer's thread program."""

    triangles_per_cycle: float = param(0.46, unit="triangles/cycle", doc="primitive assembly and setup rate of "
                                       "the fixed-function front end", gt=0)
    quads_per_cycle: float = param(3.72, unit="quads/cycle", doc="2x2 pixel quads the fixed-function rasterizer "
                                   "emits per cycle", gt=0)
    vertices_per_triangle: float = param(1.0, unit="vertices/triangle", doc="vertices fetched and shaded per "
                                         "triangle after the post-transform vertex cache (its average cache "
                                         "miss ratio: 0.5 at best on a closed indexed mesh, about 0.6-0.7 in a "
                                         "cache-optimised order, 3 without indices)", min=0, max=3)
    vertex_bytes: int = param(16, unit="bytes", doc="attribute bytes fetched per vertex (a float4 position; a "
                              "lit mesh adds its normal)", min=0, max=1024)
    vertex_source: Literal["device", "host"] = param(
        "device", doc="where each draw's vertex and index arrays come from: device memory (vertex buffer objects, "
                      "read at the DRAM channels' bandwidth) or host memory over the bus at host_bytes_per_cycle "
                      "(OpenGL client-side arrays, or a mesh larger than device memory): 3 32-bit indices and "
                      "half a vertex (a closed mesh's vertex array) per triangle, every draw")
    host_bytes_per_cycle: float = param(6.17, unit="bytes/cycle", doc="host-to-GPU bus bandwidth, one way, per "
                                        "core cycle (PCI Express x16: 4 GB/s at 1.x, 8 GB/s at 2.0, 31.5 GB/s at "
                                        "4.0, 63 GB/s at 5.0)", gt=0)
    vertex_instructions: int = param(20, unit="instructions", doc="scalar instructions of the vertex program "
                                     "(modelview-projection transform 16 and its output writes)", min=0)
    vertex_lanes: int = param(0, unit="lanes", doc="scalar lanes of dedicated vertex shaders (0: a unified GPU, "
                              "vertex shading runs on all the SMs' lanes)", min=0)
    setup_instructions: int = param(240, unit="instructions", doc="software rasterizer, per triangle thread, "
                                    "in single-precision issue slots: transform of 3 vertices, back-face test "
                                    "(double precision in FreePipe, at the GPU's DP rate), clipping, edge setup", min=0)
    pixel_instructions: int = param(10, unit="instructions", doc="software rasterizer, per pixel of a "
                                    "triangle's bounding box: 3 edge functions, the inside test, depth "
                                    "interpolation", min=0)
    warp_packing: Literal["submission", "tiles"] = param(
        "submission", doc="how a pixel shader's fragments fill warps: 'submission', in the trace's order, spread "
                          "evenly over ceil(4 x quads / warp_size) warps (helper lanes of partial quads counted), "
                          "so a warp may cross screen-tile edges; 'tiles', as the rasterizer walks each "
                          "triangle's tiles (Morton order inside one) and deals them to tile_owners, each packing "
                          "warp_size / 4 quads of its own tiles into a warp")
    tile: int = param(8, unit="pixels", doc="warp_packing = 'tiles': edge of the screen tiles the rasterizer walks (a "
                      "power of 2): it emits a triangle's quads tile by tile, in Morton order inside a tile (the "
                      "coarse raster's 8x8 tiles of Giesen, 'A trip through the graphics pipeline', 2011, part 6; "
                      "ATTILA's 8x8 raster tiles)", min=2, max=256)
    tile_owners: int = param(2, unit="owners", doc="warp_packing = 'tiles': units the screen's tiles are dealt to, "
                             "each packing the quads "
                             "of its own tiles into pixel-shader warps (screen-space work distribution: the TPCs, "
                             "GPCs or quad pipelines that own the tiles); tile (x, y) goes to owner (x + y) mod "
                             "this, so two tiles that share an edge never share a warp; 1: one stream, a warp "
                             "takes consecutive quads whatever their tile", min=1, max=1024)

    def __post_init__(self) -> None:
        if self.tile & (self.tile - 1):
            raise ValueError(f"tile: must be a power of 2 (the rasterizer's tiles hold whole 2x2 quads in Morton "
                             f"order), got {self.tile}; try {1 << (self.tile.bit_length() - 1)}")


def morton(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Morton (Z-order) index of small non-negative coordinates (below 2^16): x in the even bits, y in the odd."""
    def spread(v):
        v = np.asarray(v, np.int64) & 0xFFFF
        v = (v | (v << 8)) & 0x00FF00FF
        v = (v | (v << 4)) & 0x0F0F0F0F
        v = (v | (v << 2)) & 0x33333333
        return (v | (v << 1)) & 0x55555555
    return spread(x) | (spread(y) << 1)


def emission(prim: np.ndarray, pixel: np.ndarray, width: int, height: int, tile: int, owners: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fixed-function rasterizer's emission order of fragments given in submission order.

    Triangles come in submission order (a run of one primitive's fragments is a
    triangle); the rasterizer walks a triangle's tiles of ``tile`` pixels square
    in row order and emits each tile's quads in Morton order, so a quad's
    fragments follow each other. Returns ``(order, owner, quad)``: ``order[i]``
    is the submission index of the ``i``-th fragment emitted; per fragment
    ``t``, ``owner[t]`` the owner of its tile (tile ``(x, y)``: ``(x + y) mod
    owners``, as int16) and ``quad[t]`` a key of its quad, ascending in emission
    order (equal keys: one quad of one triangle).
    """
    prim = np.asarray(prim, np.int64)
    pixel = np.asarray(pixel, np.int64)
    n = len(prim)
    if not n:
        return np.zeros(0, np.int64), np.zeros(0, np.int16), np.zeros(0, np.int64)
    x, y = pixel % width, pixel // width
    tiles_x = -(-width // tile)
    tx, ty = x // tile, y // tile
    tiled = (ty * tiles_x + tx) * (tile * tile) + morton(x % tile, y % tile)
    run = np.zeros(n, np.int64)
    np.cumsum(prim[1:] != prim[:-1], out=run[1:])
    key = run * (tiles_x * -(-height // tile) * tile * tile) + tiled
    return np.argsort(key, kind="stable"), ((tx + ty) % owners).astype(np.int16), key >> 2


def per_triangle_cycles(gpu) -> float:
    """Cycles per triangle of the front end's per-triangle stages (fetch, vertex shading, setup): the slowest."""
    r, c = gpu.raster, gpu.core
    lanes = r.vertex_lanes or c.sms * c.lanes_per_sm
    if r.vertex_source == "host":
        fetch = (3 * HOST_INDEX_BYTES + MESH_VERTICES_PER_TRIANGLE * r.vertex_bytes) / r.host_bytes_per_cycle
    else:
        fetch = r.vertices_per_triangle * r.vertex_bytes / (gpu.dram.bytes_per_cycle * gpu.memory.partitions)
    shade = r.vertices_per_triangle * r.vertex_instructions / lanes
    return max(1.0 / r.triangles_per_cycle, fetch, shade)


def screen_quads(pixel: np.ndarray, width: int, height: int) -> tuple[np.ndarray, int]:
    """Each pixel's 2x2 quad of the screen (numbered row by row) and the screen's number of quads."""
    qw, qh = (width + 1) // 2, (height + 1) // 2
    pixel = np.asarray(pixel, np.int64)
    return (pixel // width // 2) * qw + (pixel % width) // 2, qw * qh


def quad_ids(prim: np.ndarray, pixel: np.ndarray, width: int, height: int) -> np.ndarray:
    """A key of each fragment's 2x2 quad within its triangle (equal keys: one quad)."""
    quad, count = screen_quads(pixel, width, height)
    return np.asarray(prim, np.int64) * count + quad


def bbox_pixels(prim: np.ndarray, pixel: np.ndarray, width: int, triangles: int) -> np.ndarray:
    """Per triangle ``0..triangles-1``, the pixels of its fragments' bounding box (at least 1: a triangle that
    covers no pixel centre still tests the pixel its bounding box rounds to). Fragments in triangle order take
    one reduction per run; others a scatter."""
    out = np.ones(triangles, np.int64)
    if not len(prim):
        return out
    x, y = pixel % width, pixel // width
    if len(prim) < 2 or bool((prim[1:] >= prim[:-1]).all()):
        runs = run_starts(prim)
        out[prim[runs]] = ((np.maximum.reduceat(x, runs) - np.minimum.reduceat(x, runs) + 1)
                           * (np.maximum.reduceat(y, runs) - np.minimum.reduceat(y, runs) + 1))
        return out
    big = np.iinfo(np.int64).max
    x0 = np.full(triangles, big, np.int64)
    y0 = np.full(triangles, big, np.int64)
    x1 = np.full(triangles, -1, np.int64)
    y1 = np.full(triangles, -1, np.int64)
    np.minimum.at(x0, prim, x)
    np.minimum.at(y0, prim, y)
    np.maximum.at(x1, prim, x)
    np.maximum.at(y1, prim, y)
    has = x1 >= 0
    out[has] = (x1[has] - x0[has] + 1) * (y1[has] - y0[has] + 1)
    return out


@register_unit
class Rasterizer(Unit):
    """The fixed-function geometry front end; built when a pass's warps come from it."""

    name = "raster"
    Config = RasterConfig
    STATS = occupancy_stats("cycles the front end spent on the submitted triangles (its slowest stage)",
                            "triangles", "triangles through the front end")

    def __init__(self, config: RasterConfig, machine):
        super().__init__(1)
        prog = machine.program
        # a sampled program's front end is the whole GPU's: every pass submits all its triangles (the sampled
        # warps wait for theirs), and only its quads are the sample's (gpusim.hw.sample); a thinned sample's,
        # per pass, the GPU's on the thinned frame
        front = prog.front_end_cycles if prog.front_end_cycles is not None else per_triangle_cycles(machine.gpu)
        self.per_triangle = list(front) if isinstance(front, (list, tuple)) else [front] * len(prog.passes)
        self.quad_rate = config.quads_per_cycle
        fe = [p for p in prog.passes if p.warp_triangles is not None]
        self.requests = [sum(p.triangles for p in fe)]
        self.busy_fp = [sum(math.ceil(self._span(p) * FP) for p in fe)]
        if prog.thinning is not None:        # a thinned sample: the run's, each pass's over its share of the work
            self.run_busy_fp = [sum(round(math.ceil(self._span(p) * FP) / prog.thinning[p.index]) for p in fe)]

    @classmethod
    def needed(cls, program, gpu) -> bool:
        return any(p.warp_triangles is not None for p in program.passes)

    def _span(self, p) -> float:
        return max(p.triangles * self.per_triangle[p.index], p.quads / self.quad_rate)

    def warp_ready(self, p, start: int) -> list | None:
        """The cycle each warp of pass ``p`` may start (its fragments' triangles out of the front end), or None
        when the pass does not come through it."""
        if p.warp_triangles is None:
            return None
        out = np.maximum(p.warp_triangles * self.per_triangle[p.index], p.warp_quads / self.quad_rate)
        return (start + np.ceil(out).astype(np.int64)).tolist()

    def pass_floor(self, p, start: int) -> int:
        """The earliest cycle pass ``p`` can end: every triangle it submits through the front end."""
        return start + math.ceil(self._span(p)) if p.warp_triangles is not None else start
