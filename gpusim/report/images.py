"""PNG output of images and per-pixel maps (matplotlib's object API; no global state)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from gpusim.atomic_io import atomic_output
from gpusim.errors import GpusimError


def save_image_png(image: np.ndarray, path: str | os.PathLike) -> None:
    """Write an (H, W, 3) float image in [0, 1], row 0 = bottom, as an 8-bit PNG (atomically)."""
    from gpusim.experiment.execute import rgb8
    save_rgb8_png(rgb8(image), path)


def save_rgb8_png(rgb: np.ndarray, path: str | os.PathLike) -> None:
    """Write 8-bit (H, W, 3) rows, top row first, as a PNG (atomically)."""
    from matplotlib import image as mpimg

    with atomic_output(path) as handle:
        mpimg.imsave(handle, np.ascontiguousarray(rgb, dtype=np.uint8), format="png")


def load_rgb8_png(path: str | os.PathLike, size: tuple[int, int] | None = None) -> np.ndarray:
    """An 8-bit PNG back as (H, W, 3) uint8 rows, top row first. A file that is not a colour PNG (of
    ``size`` = (H, W), when given) fails in one line naming it."""
    from matplotlib import image as mpimg

    try:
        data = mpimg.imread(path)
    except Exception as exc:            # Pillow raises OSError, SyntaxError, ValueError, ... for a damaged file
        raise GpusimError(f"{path}: not a readable PNG image ({type(exc).__name__}: {exc}); rerun the command "
                          "that wrote it") from None
    if data.ndim != 3 or data.shape[2] not in (3, 4) or (size is not None and data.shape[:2] != tuple(size)):
        raise GpusimError(f"{path}: a {'x'.join(map(str, data.shape))} image where an RGB image"
                          + (f" of {size[1]}x{size[0]} pixels" if size is not None else "")
                          + " belongs; rerun the command that wrote it")
    if data.dtype != np.uint8:
        data = (data * 255.0 + 0.5).astype(np.uint8)
    return data[..., :3]


def save_heatmap_png(values: np.ndarray, path: str | os.PathLike, title: str, label: str,
                     log: bool = False) -> None:
    """Write an (H, W) map (row 0 = bottom) as a colour-mapped figure with a colour bar."""
    from matplotlib.colors import LogNorm

    values = np.asarray(values)
    height, width = values.shape
    # a map taller than 3:2 is drawn narrower in a figure of that height (a 1 x 16384 screen must not make a
    # figure matplotlib refuses to draw)
    fig = Figure(figsize=(6.4, 6.4 * min(height / width, 1.5) + 0.6), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    norm = LogNorm(vmin=1, vmax=max(int(values.max()), 2)) if log and values.max() > 0 else None
    shown = np.ma.masked_less_equal(values, 0) if log else values
    im = ax.imshow(shown, origin="lower", cmap="inferno", norm=norm, interpolation="nearest")
    ax.set_title(title)
    ax.set_xlabel("x (pixel)")
    ax.set_ylabel("y (pixel)")
    fig.colorbar(im, ax=ax, label=label)
    fig.tight_layout()
    with atomic_output(path) as handle:
        fig.savefig(handle, format="png")
