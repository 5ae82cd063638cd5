"""Summary statistics of a fragment trace (what ``gpusim info`` prints)."""

from __future__ import annotations

import numpy as np

from gpusim.trace import FragmentTrace


def describe(trace: FragmentTrace) -> dict:
    """Fragments, covered pixels, depth complexity (max, mean over covered pixels,
    histogram {fragments per pixel: pixels}) and the transparent share.

    ``primitives`` counts the primitives with at least one fragment; ``primitives_submitted`` the
    triangles the scene sent to the rasterizer (the trace's metadata; None when it does not say), which
    includes those that made no fragment: culled, clipped away, off screen, or too thin to cover a pixel
    centre."""
    counts = trace.depth_complexity().ravel()
    covered = counts[counts > 0]
    hist = np.bincount(covered) if covered.size else np.zeros(1, np.int64)
    n = len(trace)
    transparent = int(n - np.count_nonzero(trace.opaque))
    drawn = int(np.unique(trace.prim).size) if n else 0
    submitted = trace.meta.get("primitives")
    if not isinstance(submitted, int) or isinstance(submitted, bool) or submitted < drawn:
        submitted = None                 # a CSV import or a trace from elsewhere: only the fragments tell
    return {
        "width": trace.width, "height": trace.height, "fragments": n,
        "primitives": drawn,
        "primitives_submitted": submitted,
        "covered_pixels": int(covered.size),
        "covered_share": covered.size / trace.pixel_count,
        "depth_complexity": {
            "max": int(covered.max()) if covered.size else 0,
            "mean": float(covered.mean()) if covered.size else 0.0,
            "histogram": {int(k): int(v) for k, v in enumerate(hist) if k > 0 and v > 0},
        },
        "transparent_fragments": transparent,
        "transparent_share": transparent / n if n else 0.0,
        "meta": {k: v for k, v in trace.meta.items() if k != "scene_config"},
    }


def bucket_histogram(histogram: dict[int, int]) -> list[tuple[str, int]]:
    """Group a depth-complexity histogram into power-of-two buckets: 1, 2, 3-4, 5-8, ..."""
    out: dict[str, int] = {}
    for depth, pixels in sorted(histogram.items()):
        hi = 1 << max(depth - 1, 0).bit_length()
        lo = hi // 2 + 1 if hi > 1 else 1
        label = str(hi) if lo == hi else f"{lo}-{hi}"
        out[label] = out.get(label, 0) + pixels
    return list(out.items())
