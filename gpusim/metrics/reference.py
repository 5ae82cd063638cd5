"""The exact order-independent-transparency reference image (the ground truth).

Per pixel, fragments are sorted by depth, nearest first; fragments of equal
depth keep their submission order (the earlier one is treated as nearer). They
are composited front to back in float64 over the background:

    C = sum_i T_i * a_i * c_i,   T_0 = 1,   T_{i+1} = T_i * (1 - a_i),
    pixel = C + T_n * background

An opaque fragment has a = 1 whatever its stored alpha, so everything behind
it contributes nothing. Colours are straight (not premultiplied). The loop runs
over *depth rank* (:func:`gpusim.metrics.composite.composite_runs`), so a
pixel with thousands of layers costs thousands of small vector steps and never
a Python loop over fragments; transmittance underflows cleanly to 0.
"""

from __future__ import annotations

import numpy as np

from gpusim.metrics.composite import composite_runs
from gpusim.trace import FragmentTrace


def depth_order(trace: FragmentTrace, pixel_ids: np.ndarray | None = None) -> np.ndarray:
    """Fragment indices sorted by (pixel, depth, submission order).

    ``pixel_ids`` may pass ``trace.pixel_ids()`` when the caller already has it.
    """
    pix = trace.pixel_ids() if pixel_ids is None else pixel_ids
    return np.lexsort((trace.z, pix))   # lexsort is stable: ties keep submission order


def composite_exact(trace: FragmentTrace, background=None) -> np.ndarray:
    """The exact reference image, (height, width, 3) float64, row 0 = bottom (window y = 0)."""
    bg = trace.background if background is None else np.asarray(background, dtype=np.float64)
    pix = trace.pixel_ids()
    order = depth_order(trace, pix)
    rgba = np.take(trace.rgba, order, axis=0)       # take: rows several times faster than rgba[order]
    alpha = np.where(trace.opaque[order], 1.0, rgba[:, 3].astype(np.float64))
    image = composite_runs(pix[order], rgba[:, :3], alpha, trace.pixel_count, bg)
    return image.reshape(trace.height, trace.width, 3)
