"""What a scheme run produces: image, structures, access plan, passes and stats."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gpusim.opplan import DEFAULT_MAX_OPS, OpPlan, OpStream, layout_bases


@dataclass(frozen=True)
class Structure:
    """A memory structure a scheme allocates.

    ``entries`` x ``entry_bytes`` is what the scheme allocates up front (as its
    paper sizes it); ``used_entries`` counts the entries that hold scene data
    once capture is over (fragments stored, counters or heads a fragment reached).
    """

    name: str
    entry_bytes: int
    entries: int
    used_entries: int
    doc: str

    @property
    def allocated_bytes(self) -> int:
        return self.entries * self.entry_bytes

    @property
    def used_bytes(self) -> int:
        return self.used_entries * self.entry_bytes


@dataclass(frozen=True)
class Stat:
    """A scheme-specific statistic with its unit and a one-line description."""

    value: Any
    unit: str
    doc: str


@dataclass(eq=False)
class CapturedLists:
    """Per-pixel fragment lists a scheme holds after capture, in its stored order.

    ``fragment`` indexes the original trace; ``pixel`` is the pixel id of each
    entry; entries of one pixel are contiguous (pixels ascending).
    """

    pixel: np.ndarray
    fragment: np.ndarray

    def of_pixel(self, pixel_id: int) -> np.ndarray:
        lo, hi = np.searchsorted(self.pixel, [pixel_id, pixel_id + 1])
        return self.fragment[lo:hi]


@dataclass(eq=False)
class SchemeResult:
    """The functional outcome of replaying one trace through one scheme."""

    scheme: str
    params: dict
    image: np.ndarray                  # (height, width, 3) float64, row 0 = bottom
    fragments: int
    pixels: int                        # pixels with at least one fragment
    structures: list[Structure]
    plan: OpPlan
    geometry_passes: int
    dropped_fragments: int             # fragments the scheme failed to keep (capacity, ties)
    overflowed_pixels: int             # pixels that lost at least one fragment
    lists: CapturedLists | None = None
    stats: dict[str, Stat] = field(default_factory=dict)
    submission: np.ndarray | None = None   # trace index of each fragment thread (after reordering)
    extras: dict[str, Any] = field(default_factory=dict)   # scheme artefacts for inspection (not stats)

    @property
    def passes(self):
        return self.plan.passes

    @property
    def footprint(self) -> dict[str, int]:
        """Allocated bytes per structure, plus ``total``."""
        out = {s.name: s.allocated_bytes for s in self.structures}
        out["total"] = sum(s.allocated_bytes for s in self.structures)
        return out

    @property
    def footprint_used(self) -> dict[str, int]:
        """Bytes holding scene data per structure, plus ``total``."""
        out = {s.name: s.used_bytes for s in self.structures}
        out["total"] = sum(s.used_bytes for s in self.structures)
        return out

    @property
    def accesses(self) -> dict[str, dict[str, int]]:
        return self.plan.accesses()

    def bases(self) -> dict[str, int]:
        return layout_bases([s.name for s in self.structures],
                            {s.name: s.allocated_bytes for s in self.structures})

    def opstream(self, max_ops: int = DEFAULT_MAX_OPS) -> OpStream:
        """Expand the plan into one row per memory operation (see gpusim.opplan)."""
        return self.plan.expand(self.bases(), max_ops)
