"""Moment-based OIT's moments and their reconstruction (Münstermann, Krumpen, Klein, Peters 2018), in float32.

Pass 1 of moment-based OIT adds, per pixel, the absorbance A = -ln(1 - a) of every fragment weighted by
functions of its warped depth z in [-1, 1]: b_0 = sum A, and

* power moments: b_j = sum A z^j, j = 1..m (m = 4 or 6);
* trigonometric moments: b_j = sum A e^(i j phi), j = 1..m (m = 4 complex moments), with the depth on
  the circle at phi = (pi - w / 2)(z + 1), so depths fill [0, 2 pi - w] and a wrapping zone of w = 0.1 pi
  separates the nearest from the farthest.

Pass 2 reconstructs, at each fragment's depth z_f, the absorbance in front of it from the normalised
moments b / b_0 (the paper's algorithms, written for any m):

1. bias the normalised moments toward a point inside the moment space: power moments
   (1 - beta) b + beta b_ref (b_ref = (0, 0.375, 0, 0.375) for 4 moments, (0, 0.48, 0, 0.451, 0, 0.45)
   for 6), trigonometric moments (1 - beta) b (toward the uniform distribution on the circle);
2. factor the moment matrix, Hankel (B_ij = b_(i+j), power) or Hermitian Toeplitz (B_ij = b_(i-j),
   trigonometric), as L D L^H (the paper's Cholesky factorisation without square roots);
3. solve B c = u(x_0) for the point x_0 of the fragment's depth (u(x) = (1, x, ..., x^k)); the kernel
   polynomial sum conj(c_j) x^j has as roots the other support points of the canonical representation
   through x_0 (power: a quadratic or a cubic with real roots; trigonometric: a quartic with roots on the
   unit circle);
4. weigh each support point x by the Christoffel function 1 / (u(x)^H B^-1 u(x)) (the weights of the
   canonical representation; the paper's code computes the same sums through an interpolating
   polynomial); the normalised absorbance is the weight of the points in front of x_0 plus
   ``overestimation`` (the paper's 0.25) times the weight at x_0: between the lower bound (0) and the
   upper bound (1). On the circle "in front" is a smaller angle, and a point in the wrapping zone (which
   no depth maps to) counts in front in proportion to how far into the zone it lies (0 at its start, 1 at
   2 pi, where the nearest depth begins). Power moments give strict bounds (Markov-Krein); on the circle
   the two sums are not strict bounds (in float64, about 4% of the fragments of random pixels fall
   outside them, by up to 0.11);
5. T = saturate(exp(-b_0 absorbance)).

Everything is float32 (complex64) arithmetic, as the shader's. The roots are closed forms written to
stay finite where the paper's plain forms divide by zero: the quadratic in its stable form, the cubic by
Blinn's homogeneous method (a kernel polynomial whose degree drops, e.g. one fragment at depth 0.5 under
the symmetric bias vector, has a root at infinity, whose weight is 0), discriminants that are never
negative in exact arithmetic clamped at 0; the quartic's roots are Ferrari's with complex arithmetic. A
step that still gives a NaN (a pivot of 0 where float32 cancels a tiny bias) gives a NaN here too, and
``saturate`` turns it into T = 0 as HLSL's does; those fragments are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

F32 = np.float32
C64 = np.complex64
#: the largest alpha a fragment's absorbance is computed from: alpha 1 would give an infinite absorbance
#: (assumed: 1 - 0.5/256, half an 8-bit step below 1)
MAX_ALPHA = F32(1.0 - 0.5 / 256)
#: radians of the circle no depth maps to, between the farthest and the nearest (trigonometric moments)
WRAPPING_ZONE = 0.1 * np.pi
#: the power moments' bias target (normalised b_1..b_m), a point inside the moment space
POWER_BIAS_VECTOR = {4: (0.0, 0.375, 0.0, 0.375), 6: (0.0, 0.48, 0.0, 0.451, 0.0, 0.45)}
#: fragments reconstructed per batch (bounds the memory of the per-fragment matrices)
BATCH = 1 << 17


@dataclass(frozen=True)
class MomentSet:
    """A configuration of moments: ``kind`` ("power" or "trigonometric") and ``count`` moments beyond b_0."""

    kind: str
    count: int

    @property
    def reals(self) -> int:
        """Real values stored beyond b_0 (a trigonometric moment is complex: two)."""
        return self.count if self.kind == "power" else 2 * self.count

    @property
    def size(self) -> int:
        """Rows of the moment matrix (Hankel: m/2 + 1; Toeplitz: m + 1)."""
        return self.count // 2 + 1 if self.kind == "power" else self.count + 1


CONFIGS = {"power4": MomentSet("power", 4), "power6": MomentSet("power", 6),
           "trig4": MomentSet("trigonometric", 4)}


def warp_depth(z: np.ndarray) -> np.ndarray:
    """Window depth in [0, 1] to [-1, 1] (one fma)."""
    return (np.asarray(z, F32) * F32(2.0) - F32(1.0)).astype(F32)


def absorbance(alpha: np.ndarray) -> np.ndarray:
    """-ln(1 - min(alpha, MAX_ALPHA)) in float32: finite for every alpha in [0, 1]."""
    a = np.minimum(np.asarray(alpha, F32), MAX_ALPHA)
    return (-np.log(F32(1.0) - a)).astype(F32)


def _phase(zw: np.ndarray) -> np.ndarray:
    return (zw * F32(np.pi - WRAPPING_ZONE / 2) + F32(np.pi - WRAPPING_ZONE / 2)).astype(F32)


def _circle(phase: np.ndarray) -> np.ndarray:
    return (np.cos(phase) + 1j * np.sin(phase)).astype(C64)


def moment_terms(zw: np.ndarray, A: np.ndarray, ms: MomentSet) -> np.ndarray:
    """(n, 1 + reals) float32: each fragment's addition to (b_0, moments) (power: A z^j; trigonometric:
    Re and Im of A e^(i j phi), interleaved)."""
    zw, A = np.asarray(zw, F32), np.asarray(A, F32)
    out = np.empty((len(zw), 1 + ms.reals), F32)
    out[:, 0] = A
    if ms.kind == "power":
        p = np.ones_like(zw)
        for j in range(1, ms.count + 1):
            p = p * zw
            out[:, j] = A * p
    else:
        x = _circle(_phase(zw))
        p = np.ones(len(zw), C64)
        for j in range(1, ms.count + 1):
            p = (p * x).astype(C64)
            out[:, 2 * j - 1] = A * p.real
            out[:, 2 * j] = A * p.imag
    return out


def _matrix(b: np.ndarray, ms: MomentSet) -> np.ndarray:
    """Lower triangle of the moment matrix (n, k, k) from normalised biased moments b (n, m + 1), b_0 = 1."""
    k = ms.size
    G = np.zeros((len(b), k, k), b.dtype)
    for i in range(k):
        for j in range(i + 1):
            G[:, i, j] = b[:, i + j] if ms.kind == "power" else b[:, i - j]
    return G


def _ldl(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """G = L D L^H from its lower triangle (no pivoting, no square roots): (L unit lower, D real)."""
    n, k = G.shape[:2]
    L = np.zeros_like(G)
    D = np.zeros((n, k), F32)
    with np.errstate(all="ignore"):
        for j in range(k):
            d = G[:, j, j].real.astype(F32)
            for m in range(j):
                d = d - (np.abs(L[:, j, m]) ** 2).astype(F32) * D[:, m]
            D[:, j] = d
            L[:, j, j] = 1
            inv = F32(1.0) / d
            for i in range(j + 1, k):
                s = G[:, i, j]
                for m in range(j):
                    s = s - L[:, i, m] * np.conj(L[:, j, m]) * D[:, m]
                L[:, i, j] = s * inv
    return L, D


def _forward(L: np.ndarray, u: np.ndarray) -> np.ndarray:
    """y with L y = u (L unit lower triangular)."""
    y = u.copy()
    with np.errstate(all="ignore"):
        for i in range(1, L.shape[1]):
            for m in range(i):
                y[:, i] = y[:, i] - L[:, i, m] * y[:, m]
    return y


def _powers(x: np.ndarray, k: int) -> np.ndarray:
    """u(x) = (1, x, ..., x^(k-1)) as (n, k)."""
    u = np.empty((len(x), k), x.dtype)
    u[:, 0] = 1
    with np.errstate(all="ignore"):
        for j in range(1, k):
            u[:, j] = u[:, j - 1] * x
    return u


def _kernel(L: np.ndarray, D: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Coefficients (n, k) of the kernel polynomial through x0: conj(c), B c = u(x0)."""
    with np.errstate(all="ignore"):
        c = _forward(L, _powers(x0, L.shape[1])) / D
        for i in range(L.shape[1] - 2, -1, -1):
            for m in range(i + 1, L.shape[1]):
                c[:, i] = c[:, i] - np.conj(L[:, m, i]) * c[:, m]
    return np.conj(c)


def _christoffel(L: np.ndarray, D: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Weight 1 / (u(x)^H B^-1 u(x)) of the canonical representation at points x (n,)."""
    y = _forward(L, _powers(x, L.shape[1]))
    with np.errstate(all="ignore"):
        return (F32(1.0) / ((np.abs(y) ** 2).astype(F32) / D).sum(axis=1, dtype=F32)).astype(F32)


def quadratic_roots(c: np.ndarray) -> list[np.ndarray]:
    """Real roots of c0 + c1 x + c2 x^2 in the stable form q = -(c1 + sign(c1) sqrt(c1^2 - 4 c0 c2)) / 2,
    roots q / c2 and c0 / q: a vanishing c2 gives a root at infinity (weight 0), not a NaN. The discriminant,
    never negative for the kernel polynomial of a valid moment vector, is clamped at 0."""
    with np.errstate(all="ignore"):
        c0, c1, c2 = c[:, 0], c[:, 1], c[:, 2]
        root = np.sqrt(np.maximum(c1 * c1 - F32(4.0) * c0 * c2, F32(0.0)))
        q = F32(-0.5) * (c1 + np.where(c1 < 0, -root, root))
        return [(q / c2).astype(F32), (c0 / q).astype(F32)]


def cubic_roots(c: np.ndarray) -> list[np.ndarray]:
    """The three real roots of c0 + c1 x + c2 x^2 + c3 x^3 by Blinn's homogeneous method ("How to solve a
    cubic equation, part 5", 2007): the largest root as X / W with W = c3, the smallest with X = -c0, the
    middle one from both, so that a vanishing c3 gives a root at infinity (weight 0), not a NaN. The
    discriminant and the depressed cubics' -C, never negative for three real roots, are clamped at 0."""
    with np.errstate(all="ignore"):
        A, B, C, D = c[:, 3], c[:, 2] * F32(1 / 3), c[:, 1] * F32(1 / 3), c[:, 0]
        d1, d2, d3 = A * C - B * B, A * D - B * C, B * D - C * C
        disc = np.sqrt(np.maximum(F32(4.0) * d1 * d3 - d2 * d2, F32(0.0)))
        half_sqrt3 = F32(np.sqrt(3.0) / 2)

        def two(lead, cbar, dbar):
            theta = np.abs(np.arctan2(lead * disc, -dbar)) * F32(1 / 3)
            scale = F32(2.0) * np.sqrt(np.maximum(-cbar, F32(0.0)))
            cos, sin = np.cos(theta), np.sin(theta)
            return scale * cos, scale * (F32(-0.5) * cos - half_sqrt3 * sin)

        x1, x3 = two(A, d1, F32(-2.0) * B * d1 + A * d2)
        xl = np.where(x1 + x3 > F32(2.0) * B, x1, x3)
        XL, WL = xl - B, A
        y1, y3 = two(D, d3, -D * d2 + F32(2.0) * C * d3)
        xs = np.where(y1 + y3 < F32(2.0) * C, y1, y3)
        XS, WS = -D, xs + C
        E, F, G = WL * WS, -XL * WS - WL * XS, XL * XS
        XM, WM = C * F - B * G, -B * F + C * E
        return [(XL / WL).astype(F32), (XM / WM).astype(F32), (XS / WS).astype(F32)]


def _horner(coef: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p(x), p'(x)) of the polynomial with coefficients coef[:, j] of x^j."""
    p = coef[:, -1].copy()
    dp = np.zeros_like(p)
    for j in range(coef.shape[1] - 2, -1, -1):
        dp = dp * x + p
        p = p * x + coef[:, j]
    return p, dp


def quartic_roots(c: np.ndarray, newton: int = 0) -> list[np.ndarray]:
    """The four complex roots of c0 + c1 x + ... + c4 x^4 (complex64), by Ferrari's method: the depressed
    quartic y^4 + p y^2 + q y + r, the resolvent cubic's root of largest size (Cardano), two quadratics;
    each root then polished by ``newton`` Newton steps (none by default: in float32 they move a transmittance by
    less than 4e-4)."""
    with np.errstate(all="ignore"):
        inv = (1 / c[:, 4]).astype(C64)
        a, b, cc, d = (c[:, j] * inv for j in (3, 2, 1, 0))
        a4 = a * F32(0.25)
        a2 = a4 * a4
        p = b - F32(6.0) * a2
        q = cc - F32(2.0) * a4 * b + F32(8.0) * a2 * a4
        r = d - a4 * cc + a2 * b - F32(3.0) * a2 * a2
        # resolvent m^3 + p m^2 + (p^2 / 4 - r) m - q^2 / 8, depressed by m = t - p / 3: t^3 + P t + Q
        P = -p * p * F32(1 / 12) - r
        Q = -p * p * p * F32(1 / 108) + p * r * F32(1 / 3) - q * q * F32(0.125)
        s = np.sqrt(Q * Q * F32(0.25) + P * P * P * F32(1 / 27))
        w = np.where(np.abs(-Q * F32(0.5) + s) >= np.abs(-Q * F32(0.5) - s), -Q * F32(0.5) + s, -Q * F32(0.5) - s)
        u = (w ** F32(1 / 3)).astype(C64)
        best = np.zeros_like(u)
        for k in range(3):
            uk = (u * C64(np.exp(2j * np.pi * k / 3))).astype(C64)
            mk = np.where(uk != 0, uk - P / (F32(3.0) * uk), 0) - p * F32(1 / 3)
            best = np.where(np.abs(mk) > np.abs(best), mk, best).astype(C64)
        sq = np.sqrt(F32(2.0) * best).astype(C64)
        t = np.where(sq != 0, F32(2.0) * q / sq, 0).astype(C64)
        roots = []
        for sign in (F32(1.0), F32(-1.0)):
            disc = np.sqrt(-(F32(2.0) * p + F32(2.0) * best + sign * t)).astype(C64)
            for sign2 in (F32(1.0), F32(-1.0)):
                roots.append(((sign * sq + sign2 * disc) * F32(0.5) - a4).astype(C64))
        monic = (c * inv[:, None]).astype(C64)
        for _ in range(newton):
            for k, x in enumerate(roots):
                f, df = _horner(monic, x)
                roots[k] = np.where(df != 0, x - f / df, x).astype(C64)
    return roots


def _parameter(x: np.ndarray) -> np.ndarray:
    """Angle of a point of the unit circle in [0, 2 pi)."""
    angle = np.arctan2(x.imag, x.real).astype(F32)
    return np.where(angle < 0, angle + F32(2 * np.pi), angle).astype(F32)


def _power_share(L: np.ndarray, D: np.ndarray, zw: np.ndarray, ms: MomentSet, overestimation: float) -> np.ndarray:
    """:func:`_absorbance_share` of power moments, the same float32 operations in the same order on one
    contiguous column per matrix entry (no (n, k) temporaries, no row sums): u(x)_0 = 1, so the first step
    of each forward substitution (u_i - L_i0 * 1) and the first Christoffel term (1 * 1 / D_0) drop a
    multiplication by 1, which is exact."""
    k = L.shape[1]
    with np.errstate(all="ignore"):
        low = {(i, m): np.ascontiguousarray(L[:, i, m]) for i in range(1, k) for m in range(i)}
        d = [np.ascontiguousarray(D[:, j]) for j in range(k)]
        first = F32(1.0) / d[0]

        def forward(x):
            y, u = [None], x
            for i in range(1, k):
                if i > 1:
                    u = u * x
                yi = u - low[i, 0]
                for m in range(1, i):
                    yi = yi - low[i, m] * y[m]
                y.append(yi)
            return y

        def christoffel(x):
            y = forward(x)
            s = first
            for j in range(1, k):
                s = s + y[j] * y[j] / d[j]
            return F32(1.0) / s

        y = forward(zw)
        c = [first] + [y[i] / d[i] for i in range(1, k)]
        for i in range(k - 2, -1, -1):
            for m in range(i + 1, k):
                c[i] = c[i] - low[m, i] * c[m]
        coef = np.stack(c, axis=1)
        roots = quadratic_roots(coef) if ms.size == 3 else cubic_roots(coef)
        share = F32(overestimation) * christoffel(zw)
        for x in roots:
            # a root at infinity weighs 0; a NaN root stays NaN (a shader's comparison with NaN is false, its
            # sum is NaN)
            w = np.where(np.isinf(x), F32(0.0), christoffel(x))
            front = (x < zw).astype(F32)
            share = share + np.where(np.isnan(x), np.nan, np.where(front > 0, w * front, F32(0.0))).astype(F32)
    return share.astype(F32)


def _absorbance_share(L: np.ndarray, D: np.ndarray, zw: np.ndarray, ms: MomentSet,
                      overestimation: float) -> np.ndarray:
    """Normalised absorbance in front of each fragment from its pixel's factored moment matrix (L, D)."""
    if ms.kind == "power":
        return _power_share(L, D, zw, ms, overestimation)
    with np.errstate(all="ignore"):
        if ms.kind == "power":
            x0, front_of = zw, zw
            coef = _kernel(L, D, x0).real.astype(F32)
            roots = quadratic_roots(coef) if ms.size == 3 else cubic_roots(coef)
            keys = roots
        else:
            x0 = _circle(_phase(zw))
            front_of = _parameter(x0)
            roots = quartic_roots(_kernel(L, D, x0).astype(C64))
            keys = [_parameter(x) for x in roots]
        share = F32(overestimation) * _christoffel(L, D, x0)
        for x, key in zip(roots, keys):
            # a root at infinity weighs 0; a NaN root stays NaN (a shader's comparison with NaN is false, its
            # sum is NaN)
            w = np.where(np.isinf(x), F32(0.0), _christoffel(L, D, x))
            front = (key < front_of).astype(F32)
            if ms.kind != "power":      # the wrapping zone: in front in proportion to how far into it
                front = np.maximum(front, np.clip((key - F32(2 * np.pi - WRAPPING_ZONE)) * F32(1 / WRAPPING_ZONE),
                                                  F32(0.0), F32(1.0)))
            share = share + np.where(np.isnan(key), np.nan, np.where(front > 0, w * front, F32(0.0))).astype(F32)
    return share.astype(F32)


def normalised(b0: np.ndarray, moments: np.ndarray, ms: MomentSet, bias: float) -> np.ndarray:
    """(n, m + 1) biased normalised moments (b_0 = 1), float32 (power) or complex64 (trigonometric)."""
    with np.errstate(all="ignore"):
        scaled = (moments * (F32(1.0) / b0)[:, None]).astype(F32)
    beta = F32(bias)
    if ms.kind == "power":
        ref = np.asarray(POWER_BIAS_VECTOR[ms.count], F32)
        out = np.empty((len(b0), ms.count + 1), F32)
        out[:, 1:] = scaled * (F32(1.0) - beta) + ref * beta
    else:
        out = np.empty((len(b0), ms.count + 1), C64)
        out[:, 1:] = (scaled[:, 0::2] + 1j * scaled[:, 1::2]) * (F32(1.0) - beta)
    out[:, 0] = 1
    return out


def factor(b0: np.ndarray, moments: np.ndarray, ms: MomentSet, bias: float) -> tuple[np.ndarray, np.ndarray]:
    """(L, D): the L D L^H factorisation of each pixel's biased normalised moment matrix, from its sums ``b0``
    (p,) and ``moments`` (p, reals) as read from storage (the same float32 operations each fragment's shader
    repeats; a pixel whose b_0 is 0 gives non-finite factors)."""
    return _ldl(_matrix(normalised(b0, moments, ms, bias), ms))


def transmittance_rows(L: np.ndarray, D: np.ndarray, b0: np.ndarray, zw: np.ndarray, ms: MomentSet,
                       overestimation: float) -> tuple[np.ndarray, np.ndarray]:
    """(T, invalid) of fragments at warped depths ``zw`` (n,) whose pixels' factors and b_0 are the rows
    ``L`` (n, k, k), ``D`` (n, k) and ``b0`` (n,) (T = saturate(exp(-b_0 share)), a NaN giving T = 0)."""
    T = np.empty(len(zw), F32)
    invalid = np.empty(len(zw), bool)
    for lo in range(0, len(zw), BATCH):
        hi = lo + BATCH
        share = _absorbance_share(L[lo:hi], D[lo:hi], zw[lo:hi], ms, overestimation)
        with np.errstate(all="ignore"):
            t = np.exp(-b0[lo:hi] * share).astype(F32)
        bad = np.isnan(t)
        invalid[lo:hi] = bad
        T[lo:hi] = np.where(bad, F32(0.0), np.clip(t, F32(0.0), F32(1.0)))
    return T, invalid


def transmittance(b0: np.ndarray, moments: np.ndarray, pix: np.ndarray, zw: np.ndarray, ms: MomentSet,
                  bias: float, overestimation: float) -> tuple[np.ndarray, np.ndarray]:
    """(T, invalid): each fragment's reconstructed transmittance in front of its warped depth ``zw``, from
    its pixel ``pix``'s sums ``b0`` (P,) and ``moments`` (P, reals) as read from storage, and whether the
    reconstruction gave a NaN (which saturate turns into T = 0). The matrix depends on the pixel only, so
    it is factored once per pixel (the same float32 operations each fragment's shader repeats). A pixel
    whose b_0 is 0 has nothing in front: T = 1 (its fragments all have alpha 0 and add nothing)."""
    n = len(zw)
    T = np.ones(n, F32)
    invalid = np.zeros(n, bool)
    lit = np.flatnonzero(b0 > 0)
    if not len(lit) or not n:
        return T, invalid
    L, D = factor(b0[lit], moments[lit], ms, bias)
    row = np.full(len(b0), -1, np.int64)
    row[lit] = np.arange(len(lit))
    for lo in range(0, n, BATCH):
        live = np.flatnonzero(row[pix[lo:lo + BATCH]] >= 0) + lo
        if not len(live):
            continue
        r = row[pix[live]]
        T[live], invalid[live] = transmittance_rows(L[r], D[r], b0[pix[live]], zw[live], ms, overestimation)
    return T, invalid
