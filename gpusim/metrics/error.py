"""Image error between a scheme's image and the exact reference.

Images are float RGB in [0, 1]. RMSE is taken over every channel of every
pixel; PSNR = 20 log10(1 / RMSE) dB (infinite for identical images); a pixel
*differs* when any channel differs by more than one 8-bit step (1/255).
"""

from __future__ import annotations

import math

import numpy as np

EIGHT_BIT_STEP = 1.0 / 255.0


def image_error(image: np.ndarray, reference: np.ndarray) -> dict:
    """``rmse``, ``psnr`` (dB, inf when equal), ``differing_pixels``, ``differing_share``, ``max_abs``."""
    image = np.asarray(image, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if image.shape != reference.shape:
        raise ValueError(f"image shape {image.shape} differs from reference shape {reference.shape}")
    diff = np.abs(image - reference)
    rmse = float(np.sqrt(np.mean(diff * diff))) if diff.size else 0.0
    psnr = math.inf if rmse == 0.0 else 20.0 * math.log10(1.0 / rmse)
    differing = int(np.count_nonzero((diff > EIGHT_BIT_STEP).reshape(-1, diff.shape[-1]).any(axis=1)))
    pixels = diff.size // diff.shape[-1] if diff.size else 0
    return {"rmse": rmse, "psnr": psnr, "differing_pixels": differing,
            "differing_share": differing / pixels if pixels else 0.0,
            "max_abs": float(diff.max()) if diff.size else 0.0}
