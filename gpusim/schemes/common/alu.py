"""ALU instruction counts of the schemes' thread programs (OpPlan.compute), from what each step does.

Counts are scalar instructions of one thread, as a GPU compiler would emit
them for the step; the timing model issues them at the SM's lanes, a warp
lasting as long as its busiest thread. They describe the schemes' programs,
not a GPU: the same counts serve every preset.
"""

from __future__ import annotations

import numpy as np

#: one compare-exchange of a register sort on (depth, payload) pairs: compare, two selects per register
COMPARE_EXCHANGE = 5
#: compositing one fragment front to back: 4 multiply-adds of the colour, the transmittance update, its test
COMPOSITE = 6
#: unpacking an 8-bit RGBA colour from a 32-bit word: 4 shifts/masks and 4 conversions
UNPACK_RGBA8 = 8
#: packing depth and colour into one word (FreePipe section 4.1.2): scale, convert, shift, mask, or
PACK_DEPTH_COLOUR = 6
#: a weight or blend factor evaluation (WBOIT's weight, an alpha blend): a few multiply-adds
WEIGHT = 6
#: count leading zeros of the four colour channels and the section's Length-table entry (TFSS, seed 003)
LEADING_ZEROS = 10
#: a compare-exchange of single-word keys (LucidRaster's 22 depth bits over a 10-bit index): a min and a max
KEY_COMPARE_EXCHANGE = 2
#: re-joining FreePipe's two 12-bit colour halves (seed 000 section 4.1.2): 2 masks, a shift, an or; then
#: 3 channel extracts and 3 conversions of the 24-bit RGB
UNPACK_SPLIT_RGB24 = 10
#: premultiplying the output colour by a weight or alpha: 3 multiplies
PREMULTIPLY = 3
#: WBOIT's resolve of one pixel: clamp accum.a (min, max), its reciprocal, 3 multiplies of accum.rgb, 1 - revealage
WBOIT_RESOLVE = 7
#: a depth-peeling fragment against the previous pass's depth: a compare and the discard it decides
PEEL_TEST = 2
#: a dual-depth-peeling fragment against the previous min and max: 2 compares (front, back), 2 selects of outputs
DUAL_PEEL_TEST = 4
#: an R-buffer fragment against its pixel's second z: a compare and the branch (blend and leave, or write back)
RECIRCULATE_TEST = 2
#: one pair of a pixel's fragments in Eq. 4's weight factors (seed 003 Figure 2-6): compare the depths, select
#: which weight takes the other's (1 - a) (2 selects), 2 multiplies
WEIGHT_FACTOR_PAIR = 5
#: reading a leading-0s-eliminated colour back (seed 003 section 3.3): the Length-table field's shift and mask,
#: then per RGB channel its bit offset (an add), a shift and a mask
LEADING_ZEROS_DECODE = 11

#: WBOIT's weight function per fragment (McGuire & Bavoil 2013 eq. 7-10, as gpusim.schemes.blending), times
#: alpha; |z| from window depth d is near far / (far - d (far - near)): an fma, a reciprocal, a multiply (3)
WBOIT_WEIGHT: dict[str, int] = {
    "constant": 0,        # w = a: nothing to evaluate
    "eq10": WEIGHT,       # 1 - d, its square and cube (2), x 3e3, max, x a
    "eq7": 3 + 12,        # |z|; z/5 and fma((z/5)^2, +1e-5); z/200 and ^2, ^4, ^6 (4); add; rcp; x 10; clamp (2); x a
    "eq8": 3 + 13,        # |z|; z/10, ^2, fma(^3, +1e-5) (3); z/200, ^2, ^4, ^6 (4); add; rcp; x 10; clamp (2); x a
    "eq9": 3 + 8,         # |z|; z/200, ^2, fma(^4, +1e-5) (3); rcp; x 0.03; clamp (2); x a
}


def compare_exchange(payload_bytes: int) -> int:
    """Instructions of one compare-exchange of (depth, payload) entries whose payload takes ``payload_bytes``
    (in 32-bit registers): the compare, then for each of the two outputs a select per register.
    ``COMPARE_EXCHANGE`` is the one-register case (a packed rgba8 colour): an RGBA32F entry costs 11."""
    return 1 + 2 * (1 + -(-int(payload_bytes) // 4))


def insertion_compares(length: np.ndarray, inversions: np.ndarray | None = None) -> np.ndarray:
    """Compares of an insertion sort per list: ``length - 1`` plus its inversions (all of them, the worst
    case, when ``inversions`` is None: n (n - 1) / 2)."""
    length = np.asarray(length, np.int64)
    if inversions is None:
        return length * (length - 1) // 2
    return np.maximum(length - 1, 0) + np.asarray(inversions, np.int64)


def bitonic_compares(length: np.ndarray) -> np.ndarray:
    """Compare-exchanges of a bitonic network per list: on the next power of two m >= n,
    (m / 2) log2(m) (log2(m) + 1) / 2; none for a list of 0 or 1."""
    length = np.asarray(length, np.int64)
    m = np.ones_like(length)
    big = length > 1
    m[big] = 1 << np.ceil(np.log2(length[big])).astype(np.int64)
    log = np.log2(m).astype(np.int64)
    return (m // 2) * log * (log + 1) // 2


def sort_compares(length: np.ndarray, method: str) -> np.ndarray:
    """Compare-exchanges per list of ``length`` elements sorted in registers by ``method`` (insertion sort at
    its worst case: lists loaded in arrival order are unsorted in general)."""
    if method == "bitonic":
        return bitonic_compares(length)
    if method == "insertion":
        return insertion_compares(length)
    raise ValueError(f"unknown sort {method!r} (valid: insertion, bitonic)")


def weight_factor_work(fragments: np.ndarray) -> np.ndarray:
    """Instructions of Eq. 2-4's read-out of a pixel with ``fragments`` visible fragments (seed 003 Figure 2-6;
    Weight-Factor and TFSS): each pair compared once (``WEIGHT_FACTOR_PAIR``), each fragment blended with its
    weight (``COMPOSITE``)."""
    m = np.asarray(fragments, np.int64)
    return m * (m - 1) // 2 * WEIGHT_FACTOR_PAIR + m * COMPOSITE

#: a shared-memory atomic add (LucidRaster's per-bin counters in a binning workgroup): the counter's
#: address (2), the atomic itself (1), the test of its result (1)
SHARED_ATOMIC = 4

#: a fragment's bucket or histogram bin in its pixel's depth range (bucket depth peeling, Liu et al. 2009):
#: z - near, the reciprocal of far - near, two multiplies (by it and by the bucket count), a convert, a clamp
BUCKET_INDEX = 6
#: one 32-bit output channel of a fragment routed over MRTs: compare the channel's number with the bucket's,
#: select the depth (or the histogram bit) or the empty value
CHANNEL_SELECT = 2
#: one 32-bit word of an occupancy histogram read back: mask the bins below the fragment's, count the bits, add
POPCOUNT_WORD = 3
#: the adaptive bucket of an occupied bin: its rank times the buckets over the occupied bins (a multiply, a
#: reciprocal, a multiply, a convert)
EQUALISE = 4
#: the composite's test of one bucket for the empty value (a compare and the branch around its compositing)
BUCKET_SCAN = 2

#: an MLAB fragment's output (Salvi & Vaidyanathan 2014): its colour premultiplied by alpha (3 multiplies) and
#: its transmittance 1 - a (1)
MLAB_FRAGMENT = PREMULTIPLY + 1
#: MLAB's merge of the two farthest of its layers + 1 entries: rgb + rgb' T (3 fmas), T T' (1), the test whether
#: the last entry is occupied and a select of each of the 4 merged values
MLAB_MERGE = 3 + 1 + 1 + 4

#: moment-based OIT's pass 1 per fragment (Münstermann et al. 2018): alpha clamp (a min), 1 - a, the logarithm
#: (log2 and a multiply) and the depth warp (an fma) = 5; then power moments: the powers z^2 .. z^m (m - 1
#: multiplies) and A z^j (m); trigonometric: the phase (an fma), sin and cos (2), the complex powers
#: e^(2 i phi) .. e^(m i phi) (m - 1 complex multiplies of 4) and A times 2m reals
MBOIT_GENERATE = {"power4": 5 + 3 + 4, "power6": 5 + 5 + 6, "trig4": 5 + 1 + 2 + 3 * 4 + 8}
#: the roots of the kernel polynomial: a quadratic in its stable form (the discriminant: a multiply, an fma, a
#: clamp; its square root; the sign select (2); an add and a multiply; 2 divisions of 2); a cubic by Blinn's
#: homogeneous method (B and C (2); the Hessian's 3 terms of 2; the discriminant (3) and its root; per end of
#: the range: D-bar (3), atan2 (8), abs and / 3 (2), the scale's clamp, root and multiply (3), sin and cos (2),
#: 2 roots (3), a select (2); the middle root (9); 3 divisions of 2); a complex quartic by Ferrari (monic form:
#: a complex reciprocal (6) and 4 complex multiplies (16); the depressed coefficients (40); the resolvent by
#: Cardano: a complex square root (8), a cube root in polar form (12), 3 candidate roots of a complex division
#: (10), a size (3) and a select (2); 3 complex square roots (24) and the 4 roots (8))
MBOIT_ROOTS = {3: 3 + 1 + 2 + 2 + 4, 4: 2 + 6 + 4 + 2 * 23 + 9 + 6, 5: 6 + 16 + 40 + 8 + 12 + 3 * 15 + 24 + 8}
#: moment-based OIT's resolve per pixel: the total transmittance exp(-b_0) (a multiply and exp2), 1 - T, the
#: reciprocal of the accumulated alpha and 3 multiplies of the accumulated colour by it and by 1 - T (6)
MBOIT_RESOLVE = 2 + 1 + 1 + 6


def mboit_reconstruct(kind: str, count: int) -> int:
    """Instructions of moment-based OIT's transmittance at one fragment's depth from ``count`` moments of
    ``kind`` ("power" or "trigonometric"; gpusim.schemes.common.moments), on a k x k moment matrix (Hankel:
    k = count / 2 + 1, real; Toeplitz: k = count + 1, complex, where an fma costs 4):

    * normalise and bias the moments: a reciprocal of b_0, a multiply and an fma per real;
    * the L D L^H factorisation: an fma per product of its sums, a multiply per entry of L, a reciprocal per
      pivot;
    * the kernel polynomial (B c = u(x_0)): forward and backward substitution, k^2 fmas, and the powers of
      x_0 (k - 1 multiplies);
    * its roots (``MBOIT_ROOTS``);
    * a Christoffel weight per support point (k of them): the powers of the point, a forward substitution,
      k squared sizes over D (an fma each) and a reciprocal; trigonometric moments also take each point's
      angle (atan2, 8) to compare;
    * per root a compare and a select-add (trigonometric: also the wrapping zone's ramp, an fma, a clamp and a
      max); then b_0 times the share, exp2 and saturate (4)."""
    complex_ = kind == "trigonometric"
    k = count // 2 + 1 if not complex_ else count + 1
    op = 4 if complex_ else 1
    reals = count * (2 if complex_ else 1)
    normalise = 1 + 2 * reals
    ldl = op * (sum(j for j in range(k)) + sum((k - 1 - j) * (j + 1) for j in range(k))) + k
    kernel = op * (k * k + k - 1)
    weight = op * ((k - 1) + k * (k - 1) // 2) + 2 * k + 1 + (8 if complex_ else 0)
    return normalise + ldl + kernel + MBOIT_ROOTS[k] + k * weight + (5 if complex_ else 2) * (k - 1) + 4
