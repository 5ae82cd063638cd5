"""LucidRaster's screen hierarchy (seed 002 section 2): bins, block-rows, blocks and half-blocks.

32x32-pixel bins; inside a bin, 32x8 block-rows, 8x8 blocks and 8x4
half-blocks, all on fixed grids. A primitive "covers" a region where it has at
least one sample there: the model works from fragments, so it knows coverage
exactly (the paper's binner estimates small quads from their bounding boxes
and may list a few more bins).

Region ids are row-major over the screen at each level; the pairs (region,
triangle) of a coarser level are derived from the finer level's pairs, so only
the finest level touches every fragment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpusim.schemes.common.arrays import lex_order, unique_ids

BIN = 32
BLOCK = 8
HALF_BLOCK_H = 4


@dataclass(frozen=True)
class Grid:
    """Region counts per row of the screen at each level."""

    width: int
    height: int

    @property
    def bins_x(self) -> int:
        return -(-self.width // BIN)

    @property
    def bins(self) -> int:
        return self.bins_x * -(-self.height // BIN)

    @property
    def blocks_x(self) -> int:
        return -(-self.width // BLOCK)

    def half_block_of_pixel(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return (np.asarray(y, np.int64) // HALF_BLOCK_H) * self.blocks_x + np.asarray(x, np.int64) // BLOCK

    def block_of_half_block(self, hb: np.ndarray) -> np.ndarray:
        return (hb // self.blocks_x) // (BLOCK // HALF_BLOCK_H) * self.blocks_x + hb % self.blocks_x

    def block_row_of_block(self, block: np.ndarray) -> np.ndarray:
        return (block // self.blocks_x) * self.bins_x + (block % self.blocks_x) // (BIN // BLOCK)

    def bin_of_block_row(self, block_row: np.ndarray) -> np.ndarray:
        return (block_row // self.bins_x) // (BIN // BLOCK) * self.bins_x + block_row % self.bins_x

    def bin_of_block(self, block: np.ndarray) -> np.ndarray:
        return self.bin_of_block_row(self.block_row_of_block(block))

    def bin_of_half_block(self, hb: np.ndarray) -> np.ndarray:
        return self.bin_of_block(self.block_of_half_block(hb))

    def bin_of_pixel(self, pixel: np.ndarray) -> np.ndarray:
        return (pixel // self.width) // BIN * self.bins_x + (pixel % self.width) // BIN


def pairs(region: np.ndarray, tri: np.ndarray, tris: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct (region, triangle) pairs: (region of each pair, triangle of each pair, pair of each input).

    Pairs come sorted by region, then triangle index (submission order).
    """
    key = np.asarray(region, np.int64) * max(tris, 1) + tri
    uniq, _, inverse = unique_ids(key)
    return uniq // max(tris, 1), uniq % max(tris, 1), inverse


# The shader's work items (nadult/lucid data/shaders), derived from what a trace holds: it carries fragments,
# not vertices, so a quad is two consecutive triangles in submission order (the paper pairs neighbours that
# share an edge) and its bin AABB is the bounding box of its samples' bins (its vertices' box may reach a bin
# further); a large triangle's bins in a bin row are the span of its samples' bins there (the scanline
# estimate of bin_counter.glsl may take a bin more).

def quad_aabbs(bins_x: int, pb_bin: np.ndarray, pb_tri: np.ndarray, quads: int) -> np.ndarray:
    """(quads, 4) bin AABB (x0, y0, x1, y1) of each quad's samples; -1 where the quad has none."""
    out = np.full((quads, 4), -1, np.int64)
    if len(pb_bin) == 0:
        return out
    q = np.asarray(pb_tri, np.int64) // 2
    bx, by = pb_bin % bins_x, pb_bin // bins_x
    lo = np.full((quads, 2), np.iinfo(np.int64).max)
    hi = np.full((quads, 2), -1, np.int64)
    np.minimum.at(lo, (q, 0), bx)
    np.minimum.at(lo, (q, 1), by)
    np.maximum.at(hi, (q, 0), bx)
    np.maximum.at(hi, (q, 1), by)
    has = hi[:, 0] >= 0
    out[has, :2], out[has, 2:] = lo[has], hi[has]
    return out


def aabb_bins(aabb: np.ndarray, bins_x: int) -> tuple[np.ndarray, np.ndarray]:
    """Every bin of each AABB row (x0, y0, x1, y1), row-major as countSmallQuadBins walks it: (row of
    ``aabb`` of each entry, bin of each entry)."""
    w = aabb[:, 2] - aabb[:, 0] + 1
    n = w * (aabb[:, 3] - aabb[:, 1] + 1)
    owner = np.repeat(np.arange(len(aabb)), n)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
    bx = aabb[owner, 0] + k % w[owner]
    by = aabb[owner, 1] + k // w[owner]
    return owner, by * bins_x + bx


def row_spans(bins_x: int, pb_bin: np.ndarray, pb_tri: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, ...]:
    """Large triangles' bins, per bin row the span of bins holding their samples (dispatchLargeTri's
    scanline): (triangle of each entry, bin of each entry, row of the entry in its triangle's rows (0 = its
    first), the triangle's rows) for the pairs where ``keep[pb_tri]``; entries by triangle, row, column."""
    sel = np.flatnonzero(keep[pb_tri]) if len(pb_tri) else np.zeros(0, np.int64)
    tri, bx, by = pb_tri[sel], pb_bin[sel] % bins_x, pb_bin[sel] // bins_x
    if len(tri) == 0:
        z = np.zeros(0, np.int64)
        return z, z, z, z
    key = tri * (int(by.max()) + 1) + by
    _, first, inv = unique_ids(key)
    m = len(first)
    x0 = np.full(m, np.iinfo(np.int64).max)
    x1 = np.full(m, -1, np.int64)
    np.minimum.at(x0, inv, bx)
    np.maximum.at(x1, inv, bx)
    row_tri, row_by = tri[first], by[first]
    # the triangle's first row and its row count (rows between its lowest and highest)
    _, tfirst, tinv = unique_ids(row_tri)
    y0 = np.full(len(tfirst), np.iinfo(np.int64).max)
    y1 = np.full(len(tfirst), -1, np.int64)
    np.minimum.at(y0, tinv, row_by)
    np.maximum.at(y1, tinv, row_by)
    n = x1 - x0 + 1
    owner = np.repeat(np.arange(m), n)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
    e_tri = row_tri[owner]
    e_bin = row_by[owner] * bins_x + x0[owner] + k
    e_row = row_by[owner] - y0[tinv[owner]]
    e_rows = (y1 - y0 + 1)[tinv[owner]]
    order = lex_order(e_tri, e_row, e_bin)
    return e_tri[order], e_bin[order], e_row[order], e_rows[order]


def rows_in_bins(region: np.ndarray, tri: np.ndarray, bins_x: int, rows_per_bin: int,
                 tris: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per (bin, triangle) with samples, from its (row region, triangle) pairs, row regions numbered
    ``row * bins_x + bin column`` (rows of ``BIN / rows_per_bin`` pixels): (sorted key bin * tris +
    triangle, rows it covers, rows from its first to its last, its first row in the bin)."""
    row, col = region // bins_x, region % bins_x
    b = (row // rows_per_bin) * bins_x + col
    r = row % rows_per_bin
    key = b * max(tris, 1) + tri
    uniq, _, inv = unique_ids(key)
    cov = np.bincount(inv, minlength=len(uniq))
    r0 = np.full(len(uniq), rows_per_bin, np.int64)
    r1 = np.full(len(uniq), -1, np.int64)
    np.minimum.at(r0, inv, r)
    np.maximum.at(r1, inv, r)
    return uniq, cov, r1 - r0 + 1, r0
