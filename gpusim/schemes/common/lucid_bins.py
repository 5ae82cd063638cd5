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


def grouped(keys: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Stable order of ``keys`` (group ids) and the start of each group in it."""
    order = lex_order(keys)
    counts = np.bincount(keys, minlength=groups)
    return order, np.cumsum(counts) - counts
