"""The k-buffer's entry formats (seed 004 section 3.2 and Table 1): what an entry holds, its bytes, how the
MRT texels hold the entries, and the image a resolve makes of what is stored.

The paper's k-buffer on current hardware is up to four RGBA32F MRTs ("With four MRTs, it is possible to
store up to 16 fragment attributes"); Table 1 compares k = 4 "RGBZ" entries with k = 16 "Z" entries.

================ ====== ===============================================================================
entry            bytes  what one entry holds
================ ====== ===============================================================================
``depth-colour`` 4 + C  a 32-bit depth and the fragment's colour in ``colour_format`` (C = 4, 8 or 16 B,
                        the colour's alpha included); one access of 4 + C bytes per entry
``rgbz``         16     one RGBA32F texel: the colour's R, G, B as float32 and the depth (float32) in A,
                        the paper's "RGBZ"; one access of 16 B per entry. No alpha and no opacity flag:
                        the resolve composites every entry with one alpha, the program's uniform (section
                        4.1's transparency: "For simplicity, we use a uniform alpha"): the scheme's
                        ``uniform_alpha``, by default the trace's single alpha (a trace whose fragments'
                        alphas differ, opaque ones counting 1, fails naming ``uniform_alpha``)
``z``            4      the depth alone, packed four to an RGBA32F texel (k = 16 fills the paper's four
                        MRTs; a k not a multiple of 4 leaves the last texel partly unused, allocated
                        whole); one access of 16 B per texel, ceil(k / 4) per fragment. No colour: the
                        resolve's deferred shading is a depth cue of the stored depth alone (grey 1 - z,
                        clamped to [0, 1], composited with that alpha), ``DEPTH_CUE`` instructions per
                        entry beyond the composite
================ ====== ===============================================================================

The image is therefore what the entries hold: an ``rgbz`` image is the exact composite's (of the kept
fragments) when every fragment has the alpha composited with, and differs where one has not; a ``z`` image
shows the depth layers only. The paper's timings are "without deferred shading"; here the resolve (a
full-screen pass: a pixel's entries read once, composited) is timed in every format.
The depth keys (and so the order) are those of the 32-bit depth in every format.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from gpusim.errors import GpusimError
from gpusim.schemes.base import composite_image, composite_stored
from gpusim.schemes.common.storage import COLOUR_BYTES, DEPTH_BYTES

EntryFormat = Literal["depth-colour", "rgbz", "z"]
#: an RGBA32F texel: one MRT's share of a pixel
TEXEL_BYTES = 16
#: the ``z`` format's deferred shading per entry: the grey 1 - z (one subtract; the composite uses it as a scalar)
DEPTH_CUE = 1
ENTRY_DOC = ("what an entry stores: 'depth-colour' a 32-bit depth and the colour in colour_format (4 + 4/8/16 B), "
             "'rgbz' one RGBA32F texel of RGB + depth (16 B; composited with uniform_alpha), 'z' the depth alone "
             "(4 B, four to an RGBA32F texel; the image is a depth cue, grey 1 - z, at uniform_alpha)")
UNIFORM_ALPHA_DOC = ("alpha, 0 to 1, the resolve gives every entry of an 'rgbz' or 'z' k-buffer (they store none: "
                     "the program's uniform, as the paper's); default: the trace's single alpha (a trace whose "
                     "alphas differ fails); unused with 'depth-colour'")


def check_entry(entry: str, colour_format: str) -> None:
    """Fail (ValueError naming ``colour_format``) where the entry format fixes the colour's storage."""
    if entry != "depth-colour" and colour_format != "rgba32f":
        what = "float32 R, G, B in its RGBA32F texel" if entry == "rgbz" else "no colour"
        raise ValueError(f"colour_format: entry = {entry!r} stores {what}, not {colour_format!r}; leave "
                         "colour_format at 'rgba32f' or set entry = 'depth-colour'")


def resolve_alpha(entry: str, uniform_alpha: float | None, groups) -> float:
    """The alpha an ``rgbz`` or ``z`` resolve composites every entry with: ``uniform_alpha``, or where it is
    None the single value of ``groups.alpha`` (a PixelGroups': the fragments' effective alphas, opaque ones 1;
    the alpha the application would set as its uniform); 1.0 for no fragments or ``depth-colour`` (unused)."""
    if uniform_alpha is not None:
        return float(uniform_alpha)
    if entry == "depth-colour" or not groups.n:
        return 1.0
    alpha = groups.alpha
    lo, hi = float(alpha.min()), float(alpha.max())
    if lo != hi:
        raise GpusimError(f"uniform_alpha: entry = {entry!r} stores no alpha but this trace's alpha ranges "
                          f"{lo:g}..{hi:g} (opaque = 1); set uniform_alpha to the one to composite with")
    return lo


def entry_bytes(entry: str, colour_format: str) -> int:
    """Bytes of one entry."""
    if entry == "rgbz":
        return TEXEL_BYTES
    if entry == "z":
        return DEPTH_BYTES
    return DEPTH_BYTES + COLOUR_BYTES[colour_format]


def per_access(entry: str) -> int:
    """Entries one read or write of the k-buffer moves: a ``z`` texel holds four."""
    return TEXEL_BYTES // DEPTH_BYTES if entry == "z" else 1


def access_layout(entry: str, colour_format: str, k: int) -> tuple[int, int]:
    """(accesses per pixel for its k entries, bytes of each): k entries, or ceil(k / 4) texels of ``z``."""
    per = per_access(entry)
    return -(-k // per), per * entry_bytes(entry, colour_format)


def payload_bytes(entry: str, colour_format: str) -> int:
    """Bytes an entry holds beside its depth (what a compare-exchange moves with it)."""
    return entry_bytes(entry, colour_format) - DEPTH_BYTES


def resolve_alu(entry: str) -> int:
    """Instructions per entry a resolve spends making its colour before compositing it."""
    return DEPTH_CUE if entry == "z" else 0


def entry_image(trace, pix: np.ndarray, order: np.ndarray, entry: str, colour_format: str,
                uniform_alpha: float, order_pix: np.ndarray | None = None) -> np.ndarray:
    """Image of fragments ``order`` (grouped by pixel, in compositing order) as entries of format ``entry``
    hold them: ``depth-colour`` their colour in ``colour_format`` (opaque ones at alpha 1); ``rgbz`` their
    float32 R, G, B at ``uniform_alpha``; ``z`` the grey 1 - z of their depth at ``uniform_alpha``.
    ``order_pix`` is ``pix[order]`` when the caller has it."""
    if entry == "depth-colour":
        return composite_stored(trace, pix, order, colour_format, order_pix)
    if entry == "rgbz":
        rgb = np.take(trace.rgba[:, :3], order, axis=0).astype(np.float32)
    else:
        grey = np.clip(np.float32(1.0) - np.take(trace.z, order).astype(np.float32), 0, 1)
        rgb = np.repeat(grey[:, None], 3, axis=1)
    alpha = np.full(len(order), uniform_alpha, np.float32)
    return composite_image(trace, pix[order] if order_pix is None else order_pix, np.c_[rgb, alpha], alpha)
