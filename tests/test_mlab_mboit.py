"""Multi-layer alpha blending (mlab) and moment-based OIT (mboit) against the exact reference (issue 19).

Hand-computed pixels of 2-4 fragments; MLAB equal to the reference while a pixel has at most ``layers``
fragments and to an independent per-pixel re-implementation beyond; MBOIT exact on two and three depths
where its canonical representation can hold them (overestimation 0), within the bound its normalisation
promises everywhere (docs/schemes.md), finite on the stiff cases; access counts, footprints and ALU work
as the docs state them; every timing level runs.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_trace
from hypothesis import given
from test_properties import SETTINGS, assert_close, f32_tolerance, traces

from gpusim.hw import load_gpu
from gpusim.metrics import composite_exact
from gpusim.replay import run_timing
from gpusim.schemes import make_scheme
from gpusim.schemes.common import moments as M
from gpusim.schemes.common.alu import (COMPOSITE, MBOIT_GENERATE, MBOIT_RESOLVE, MLAB_FRAGMENT, MLAB_MERGE,
                                       PREMULTIPLY, compare_exchange, mboit_reconstruct)
from gpusim.schemes.common.depthkey import depth_key
from gpusim.schemes.common.storage import rounder

BG = [0.2, 0.4, 0.6]
BLACK = {"background": [0.0, 0.0, 0.0]}
STEP = 1 / 510                      # half an 8-bit step


def run(name, trace, **params):
    return make_scheme(name, params).run(trace)


def pixel(zs, rgba, meta=BLACK, width=1):
    """Fragments on pixel 0 of a ``width`` x 1 screen, in this submission order."""
    n = len(zs)
    return make_trace(np.zeros(n, int), np.zeros(n, int), zs, rgba=rgba, width=width, height=1, meta=meta)


def one_pixel(n, alpha=None, z=None, seed=0):
    """``n`` fragments on pixel 0 of a 2 x 1 screen: distinct depths in [0, 1] (both ends included) in random
    order, or all at ``z``; random colours; ``alpha`` (default: uniform)."""
    rng = np.random.default_rng(seed)
    zs = rng.permutation(np.linspace(0, 1, n)) if z is None else np.full(n, z)
    a = rng.random(n) if alpha is None else np.full(n, alpha)
    return pixel(zs, np.c_[rng.random((n, 3)), a], {"background": BG}, width=2)


def random_trace(n=2000, side=8, seed=0, alpha=None):
    rng = np.random.default_rng(seed)
    a = rng.random(n) if alpha is None else np.full(n, alpha)
    return make_trace(rng.integers(0, side, n), rng.integers(0, side, n), rng.random(n).astype(np.float32),
                      rgba=np.c_[rng.random((n, 3)), a], width=side, height=side, meta={"background": BG})


STIFF = {
    "1,000 layers": lambda: one_pixel(1000, seed=1),
    "300 layers of alpha 0": lambda: one_pixel(300, alpha=0.0),
    "300 layers of alpha 1": lambda: one_pixel(300, alpha=1.0),
    "300 layers of alpha 0.01": lambda: one_pixel(300, alpha=0.01),
    "300 layers of alpha 0.99": lambda: one_pixel(300, alpha=0.99),
    "6 at depth 0": lambda: one_pixel(6, z=0.0),
    "6 at depth 0.5": lambda: one_pixel(6, z=0.5),
    "6 at depth 1": lambda: one_pixel(6, z=1.0),
    "one at depth 0": lambda: one_pixel(1, z=0.0),
    "one at depth 1": lambda: one_pixel(1, z=1.0),
    "depths 0 and 1": lambda: pixel([1.0, 0.0], [[1, 0, 0, 0.5], [0, 1, 0, 0.5]]),
}


# ---------------------------------------------------------------------- MLAB
def test_mlab_merges_the_two_farthest_by_hand():
    # a = 0.5 everywhere, rgba32f layers: every value is a binary fraction, so float32 is exact. Two layers:
    # R at 0.2 and G at 0.4 fill them; B at 0.8 merges into G's entry: (0, .5, .25), T .25, depth 0.4; W at 0.6
    # then lands behind that entry and merges into it: (0, .5, .25) + .25 (.5, .5, .5) = (.125, .625, .375).
    # Resolve: R + .5 entry = (.5625, .3125, .1875). The exact order R G W B weighs W by .125, not .0625
    # (composited behind B): (.625, .375, .1875).
    t = pixel([0.2, 0.4, 0.8, 0.6], [[1, 0, 0, .5], [0, 1, 0, .5], [0, 0, 1, .5], [1, 1, 1, .5]])
    res = run("mlab", t, layers=2, colour_format="rgba32f")
    assert res.image[0, 0].tolist() == [0.5625, 0.3125, 0.1875]
    assert composite_exact(t)[0, 0].tolist() == [0.625, 0.375, 0.1875]
    assert (res.stats["merges"].value, res.stats["merged_pixels"].value) == (2, 1)
    # submitted front to back, the merges are in depth order: exact
    ordered = pixel([0.2, 0.4, 0.6, 0.8], [[1, 0, 0, .5], [0, 1, 0, .5], [1, 1, 1, .5], [0, 0, 1, .5]])
    assert run("mlab", ordered, layers=2, colour_format="rgba32f").image[0, 0].tolist() == [0.625, 0.375, 0.1875]
    # four layers hold all four: exact whatever the order
    assert run("mlab", t, colour_format="rgba32f").image[0, 0].tolist() == [0.625, 0.375, 0.1875]
    assert run("mlab", t, colour_format="rgba32f").stats["merges"].value == 0


def test_mlab_rounds_its_rgba8_layers_by_hand():
    # one fragment, c = (1, 0.2, 0), a = 0.3 over black: a c = (.3, .06, 0) and T = .7 stored as k/255
    t = pixel([0.5], [[1, 0.2, 0, 0.3]])
    expected = np.rint(np.array([0.3, 0.06, 0.0], np.float32) * 255) / 255
    assert np.allclose(run("mlab", t).image[0, 0], expected, atol=1e-7)
    # equal depths: the later fragment goes behind (first submitted nearer), as the reference
    ties = pixel([0.5, 0.5], [[1, 0, 0, 0.5], [0, 1, 0, 0.5]])
    assert np.allclose(run("mlab", ties, colour_format="rgba32f").image, composite_exact(ties), atol=1e-7)


@SETTINGS
@given(trace=traces(per_pixel=4))
def test_mlab_within_its_layers_is_the_sorted_composite(trace):
    """At most ``layers`` fragments a pixel: nothing merges, and the image is the exact composite with each
    layer's premultiplied colour and transmittance rounded once (rgba32f: float32 only; rgba8: within
    sum_k T_k (|d(a c)| + |d T|) <= 2/510 per layer, weighted by the transmittance in front)."""
    exact = composite_exact(trace)
    m = trace.depth_complexity()
    wide = run("mlab", trace, colour_format="rgba32f")
    assert wide.stats["merges"].value == 0
    assert_close(wide.image, exact, f32_tolerance(m) + 1e-6, "mlab rgba32f within its layers")
    assert_close(run("mlab", trace).image, exact, f32_tolerance(m) + 2 * STEP * m + 1e-6, "mlab rgba8")


def mlab_reference(trace, layers, fmt):
    """MLAB per pixel with Python lists (an independent re-implementation): insertion behind equal depths, the
    two farthest merged on overflow, rounded to ``fmt``, the resolve clamped to [0, 1]."""
    rnd = rounder(fmt)
    pix, key = trace.pixel_ids(), depth_key(trace.z)
    alpha = np.where(trace.opaque, np.float32(1), trace.rgba[:, 3]).astype(np.float32)
    entries = {}
    for f in range(len(trace)):
        if alpha[f] == 0:
            continue
        a = alpha[f]
        rgb = rnd(trace.rgba[f, :3] * a)
        new = (int(key[f]), rgb, rnd(np.float32(1) - a))
        lst = entries.setdefault(int(pix[f]), [])
        at = sum(1 for e in lst if e[0] <= new[0])
        lst.insert(at, new)
        if len(lst) > layers:
            (k1, c1, t1), (_, c2, t2) = lst[-2], lst[-1]
            lst[-2:] = [(k1, rnd(c1 + c2 * t1), rnd(t1 * t2))]
    image = np.empty((trace.pixel_count, 3), np.float32)
    image[:] = trace.background.astype(np.float32)
    for p, lst in entries.items():
        colour, trans = np.zeros(3, np.float32), np.float32(1)
        for _, c, t in lst:
            colour = colour + trans * c
            trans = trans * t
        image[p] = np.clip(colour + trans * trace.background.astype(np.float32), 0, 1)
    return image.reshape(trace.height, trace.width, 3)


@pytest.mark.parametrize("layers, fmt", [(2, "rgba8"), (4, "rgba8"), (4, "rgba32f"), (3, "rgba16f")])
def test_mlab_equals_a_per_pixel_reimplementation(layers, fmt):
    for trace in (random_trace(3000, 6, seed=layers), STIFF["1,000 layers"](), STIFF["6 at depth 0.5"](),
                  STIFF["300 layers of alpha 0.99"]()):
        res = run("mlab", trace, layers=layers, colour_format=fmt)
        assert_close(res.image, mlab_reference(trace, layers, fmt), 1e-6, f"mlab {layers} {fmt}")


@pytest.mark.parametrize("layers, fmt", [(2, "rgba8"), (4, "rgba8"), (4, "rgba32f"), (1, "rgba8")])
def test_mlab_compiled_and_numpy_paths_agree_bit_for_bit(monkeypatch, layers, fmt):
    """The fragments past a pixel's first layers run in a numba kernel where numba is, else rank by rank in
    numpy: the same images and merge counts exactly (the kernel's float32 operations are numpy's, unfused)."""
    from gpusim.jit import numba_usable
    from gpusim.schemes import mlab
    if not numba_usable():
        pytest.skip("numba is not installed: only the numpy path exists")
    traces = (random_trace(3000, 6, seed=layers), STIFF["1,000 layers"](), STIFF["300 layers of alpha 0.99"]())
    compiled = [run("mlab", t, layers=layers, colour_format=fmt) for t in traces]
    assert mlab._KERNEL and mlab._KERNEL[0] is not None
    monkeypatch.setattr(mlab, "_KERNEL", [None])
    for trace, got in zip(traces, compiled):
        want = run("mlab", trace, layers=layers, colour_format=fmt)
        assert np.array_equal(got.image, want.image)
        assert got.stats["merges"].value == want.stats["merges"].value > 0


@pytest.mark.parametrize("moments", ["power4", "power6", "trig4"])
def test_mboit_transmittance_is_the_same_per_rank_or_gathered(monkeypatch, moments):
    """Large ranks' transmittances are computed a rank's block at a time, small ones together with their pixels'
    factors gathered: either way the same float32 operations per fragment, the same image and counts."""
    from gpusim.schemes import mboit
    traces = (random_trace(3000, 6, seed=1), STIFF["1,000 layers"](), STIFF["300 layers of alpha 0.99"]())
    got = {}
    for small in (0, 10**9):                 # every rank a block of its own; every rank gathered
        monkeypatch.setattr(mboit, "SMALL_BLOCK", small)
        got[small] = [run("mboit", t, moments=moments) for t in traces]
    for a, b in zip(got[0], got[10**9]):
        assert np.array_equal(a.image, b.image) and a.stats == b.stats


def test_mlab_discards_alpha_0_and_orders_its_rmw_in_both_hardware_modes():
    t = random_trace(500, 4, seed=3)
    rgba = t.rgba.copy()
    rgba[::5, 3] = 0.0                                        # every fifth fragment invisible
    t = make_trace(t.x, t.y, t.z, rgba=rgba, width=4, height=4, meta={"background": BG})
    kept = int(np.count_nonzero(rgba[:, 3] > 0))
    blender, rov = run("mlab", t), run("mlab", t, hw="rov")
    assert np.array_equal(blender.image, rov.image)
    assert blender.stats["discarded_fragments"].value == len(t) - kept
    P, L = t.pixel_count, 4
    assert blender.accesses == {"layers": {"store": P * L, "program_blend": kept, "load": P * L}}
    assert rov.accesses == {"layers": {"store": P * L, "scoreboard": kept, "rmw_read": L * kept,
                                       "rmw_write": L * kept, "load": P * L}}
    assert blender.footprint == {"layers": 8 * L * P, "total": 8 * L * P}      # 32-bit depth + rgba8
    assert run("mlab", t, colour_format="rgba32f").footprint["layers"] == 20 * L * P
    work = {(g.pass_index, int(g.instructions[0])) for g in rov.plan.groups if g.is_compute}
    assert work == {(1, MLAB_FRAGMENT), (1, L * compare_exchange(4) + MLAB_MERGE)} | {
        (2, int(g.instructions[0])) for g in rov.plan.groups if g.is_compute and g.pass_index == 2}
    resolve = [g for g in blender.plan.groups if g.is_compute and g.pass_index == 2][0]
    count = np.bincount(t.pixel_ids()[rgba[:, 3] > 0], minlength=P)
    assert np.array_equal(resolve.instructions, np.minimum(count, L) * COMPOSITE)


# ---------------------------------------------------------------------- MBOIT
SINGLE = {"precision": "single", "accum_format": "rgba32f"}


@pytest.mark.parametrize("moments", ["power4", "power6", "trig4"])
def test_mboit_two_fragments_by_hand(moments):
    """Red a = .5 at z .25 in front of green a = .75 at z .75, over black: A = ln 2 and ln 4, b_0 = ln 8. Any of
    the configurations holds two depths exactly, so with the overestimation at 0 T(front) = 1 and
    T(back) = 1/2, the weights (.5, .375) normalise to the exact (.5, .375, 0). The paper's overestimation of
    0.25 adds a quarter of each fragment's own absorbance: T = 2^-.25 and 2^-1.5, weights .42045 and .26517,
    colour (.61323, .38677, 0) times 1 - 1/8 = (.53658, .33842, 0)."""
    t = pixel([0.75, 0.25], [[0, 1, 0, 0.75], [1, 0, 0, 0.5]])
    lower = run("mboit", t, moments=moments, overestimation=0.0, **SINGLE)
    assert np.allclose(lower.image[0, 0], [0.5, 0.375, 0.0], atol=2e-4)
    default = run("mboit", t, moments=moments, **SINGLE)
    w = np.array([0.5 * 2 ** -0.25, 0.75 * 2 ** -1.5])
    expected = np.array([w[0], w[1], 0.0]) / w.sum() * (1 - 1 / 8)
    assert np.allclose(default.image[0, 0], expected, atol=2e-4)
    assert np.allclose(expected, [0.53658, 0.33842, 0.0], atol=1e-5)
    assert default.stats["invalid_reconstructions"].value == 0


def test_mboit_one_fragment_is_exact_and_few_depths_fit_the_canonical_representation():
    # one fragment: the normalisation leaves its colour, b_0 gives exactly its alpha (up to b_0's rounding)
    t = pixel([0.3], [[0.9, 0.5, 0.1, 0.4]], {"background": BG})
    for params, tol in (({}, 2e-3), (SINGLE, 1e-5)):
        assert np.allclose(run("mboit", t, **params).image, composite_exact(t), atol=tol)
    # the canonical representation through a fragment's depth has 3 (power4), 4 (power6) or 5 (trig4) support
    # points: a pixel of that many depths is held exactly at each of them (overestimation 0), one more is not
    zs = [0.5, 0.1, 0.8, 0.3, 0.65, 0.9]
    rgba = [[0, 0, 1, 0.6], [1, 0, 0, 0.3], [0, 1, 0, 0.5], [1, 1, 0, 0.4], [0, 1, 1, 0.7], [1, 0, 1, 0.5]]
    for moments, points in (("power4", 3), ("power6", 4), ("trig4", 5)):
        for n, close in ((points, True), (points + 1, False)):
            few = pixel(zs[:n], rgba[:n])
            image = run("mboit", few, moments=moments, overestimation=0.0, **SINGLE).image
            assert np.allclose(image, composite_exact(few), atol=5e-4) == close, (moments, n)


def test_power_moments_bound_the_absorbance_in_front():
    """Markov-Krein: with power moments the lower (overestimation 0) and upper (1) sums bracket the true
    normalised absorbance in front of every fragment (single precision, a bias of 5e-6: within 2e-3). On
    the circle they are no strict bounds (docs/schemes.md): most fragments lie between them."""
    rng = np.random.default_rng(2)
    P = 400
    pix = np.repeat(np.arange(P), rng.integers(1, 30, P))
    z, a = rng.random(len(pix)).astype(np.float32), rng.random(len(pix)).astype(np.float32)
    A = M.absorbance(a).astype(np.float64)
    same = pix[:, None] == pix[None, :]
    true = (same * (z[None, :] < z[:, None]) * A[None, :]).sum(axis=1) / np.bincount(pix, weights=A)[pix]
    zw = M.warp_depth(z)
    for name, ms in M.CONFIGS.items():
        sums = np.zeros((P, 1 + ms.reals))
        np.add.at(sums, pix, M.moment_terms(zw, M.absorbance(a), ms).astype(np.float64))
        sums = sums.astype(np.float32)
        L, D = M._ldl(M._matrix(M.normalised(sums[:, 0], sums[:, 1:], ms, 5e-6), ms))
        lower = M._absorbance_share(L[pix], D[pix], zw, ms, 0.0)
        upper = M._absorbance_share(L[pix], D[pix], zw, ms, 1.0)
        inside = (lower - 2e-3 <= true) & (true <= upper + 2e-3)
        assert inside.all() if ms.kind == "power" else inside.mean() > 0.9, (name, inside.mean())


def convex_bound(trace, res) -> np.ndarray:
    """(H, W) bound on |MBOIT - exact| (docs/schemes.md): both are (1 - T) times an average of the pixel's
    colours plus T background, so they differ by at most (1 - T) (the colours' range, largest channel) plus
    |T' - T| (T' MBOIT's total transmittance, exp(-b_0) with alpha clamped at 1 - 0.5/256 and b_0 summed
    with rounding: relative error g = m u, u its format's unit roundoff, moves T by at most b_0 g T), plus a
    relative 4u of the colour for the rounded accumulation. Pixels whose weights all rounded to 0
    (``zero_weight_pixels``, black) are left to that stat."""
    pix, P = trace.pixel_ids(), trace.pixel_count
    alpha = np.where(trace.opaque, 1.0, trace.rgba[:, 3].astype(np.float64))
    lo = np.full((P, 3), np.inf)
    hi = np.full((P, 3), -np.inf)
    np.minimum.at(lo, pix, trace.rgba[:, :3])
    np.maximum.at(hi, pix, trace.rgba[:, :3])
    spread = np.where(np.isfinite(lo), hi - lo, 0).max(axis=1)
    with np.errstate(divide="ignore"):
        T = np.exp(np.bincount(pix, weights=np.log1p(-alpha), minlength=P))
    A = -np.log1p(-np.minimum(alpha, float(M.MAX_ALPHA)))
    b0 = np.bincount(pix, weights=A, minlength=P)
    clamped = np.exp(-b0)
    m = np.bincount(pix, minlength=P)
    u = 2.0 ** -11 if res.params["precision"] == "half-all" else 2.0 ** -24      # b_0's format
    g = m * u
    moved = np.abs(clamped - T) + b0 * g * clamped / np.maximum(1 - g, 1e-9) + 1e-5
    acc_u = 2.0 ** -11 if res.params["accum_format"] == "rgba16f" else 2.0 ** -24
    bound = (1 - T) * spread + moved + 4 * m * acc_u + 1e-5
    return bound.reshape(trace.height, trace.width)


VARIANTS = [{}, {"moments": "power6"}, {"moments": "trig4"}, {"precision": "single"},
            {"moments": "power6", "precision": "single"}, {"moments": "trig4", **SINGLE},
            {"moments": "trig4", "precision": "half-all"}]


@pytest.mark.parametrize("params", VARIANTS, ids=lambda p: "-".join(map(str, p.values())) or "defaults")
@pytest.mark.parametrize("case", list(STIFF))
def test_mboit_stiff_cases_are_finite_and_within_the_bound(case, params):
    trace = STIFF[case]()
    res = run("mboit", trace, **params)
    assert np.isfinite(res.image).all() and (res.image >= 0).all() and (res.image <= 1).all()
    assert res.stats["invalid_reconstructions"].value == 0, case
    assert res.stats["accumulation_overflow"].value == 0
    bound = convex_bound(trace, res)
    if res.stats["zero_weight_pixels"].value:       # hundreds of nearly opaque layers: every T a underflows
        assert params.get("accum_format") != "rgba32f", case
        bound[0, 0] = np.inf
    assert_close(res.image, composite_exact(trace), bound, f"mboit {params} on {case}")


@pytest.mark.parametrize("case", ["1,000 layers", "300 layers of alpha 1", "6 at depth 0.5", "depths 0 and 1"])
def test_mlab_stiff_cases_are_finite(case):
    trace = STIFF[case]()
    for layers in (2, 4):
        res = run("mlab", trace, layers=layers)
        assert np.isfinite(res.image).all() and (res.image >= 0).all() and (res.image <= 1).all()
        assert res.dropped_fragments == 0
    if case == "6 at depth 0.5":        # equal depths: first submitted nearer, merged in that order
        assert np.allclose(run("mlab", trace, layers=2, colour_format="rgba32f").image, composite_exact(trace),
                           atol=1e-6)


@pytest.mark.parametrize("params", VARIANTS[:3], ids=["power4", "power6", "trig4"])
def test_mboit_on_random_pixels_is_within_the_bound_and_nearly_order_independent(params):
    trace = random_trace(1000, 8, seed=7)
    res = run("mboit", trace, **params)
    assert res.stats["invalid_reconstructions"].value == 0
    exact = composite_exact(trace)
    assert_close(res.image, exact, convex_bound(trace, res), f"mboit {params}")
    rmse = float(np.sqrt(np.mean((res.image - exact) ** 2)))
    assert 1e-3 < rmse < 0.1                        # approximate, and far nearer than unsorted blending
    assert rmse < float(np.sqrt(np.mean((run("alpha-blend", trace).image - exact) ** 2))) / 2
    # another submission order changes only the rounding of the half-float sums
    perm = np.random.default_rng(1).permutation(len(trace))
    shuffled = make_trace(trace.x[perm], trace.y[perm], trace.z[perm], rgba=trace.rgba[perm], width=8, height=8,
                          meta=dict(trace.meta))
    assert np.abs(run("mboit", shuffled, **params).image - res.image).max() < 0.02


def test_mboit_footprint_accesses_and_alu_work():
    t = random_trace(400, 4, seed=2)
    n, P = len(t), t.pixel_count
    expected = {"power4": (4, 4 * 2, [4]), "power6": (4, 6 * 2, [4, 2]), "trig4": (4, 8 * 2, [4, 4])}
    for moments, (zb, mb, targets) in expected.items():
        res = run("mboit", t, moments=moments)
        assert res.footprint == {"zeroth_moment": zb * P, "moments": mb * P, "accumulation": 8 * P,
                                 "total": (zb + mb + 8) * P}
        assert res.stats["moment_bits"].value == 8 * (zb + mb) == {"power4": 96, "power6": 128, "trig4": 160}[moments]
        assert run("mboit", t, moments=moments, precision="half-all").stats["moment_bits"].value == 8 * (2 + mb)
        assert res.accesses == {"zeroth_moment": {"blend": n, "load": n + P},
                                "moments": {"blend": len(targets) * n, "load": len(targets) * n},
                                "accumulation": {"blend": n, "load": P}}
        stream = res.opstream()
        moment_rows = stream.structure == stream.structures.index("moments")
        assert sorted(set(stream.bytes[moment_rows].tolist())) == sorted({2 * c for c in targets})
        ms = M.CONFIGS[moments]
        work = [(g.pass_index, int(g.instructions[0])) for g in res.plan.groups if g.is_compute]
        assert work == [(0, MBOIT_GENERATE[moments]), (1, mboit_reconstruct(ms.kind, ms.count) + PREMULTIPLY),
                        (2, MBOIT_RESOLVE + COMPOSITE)]
    assert run("mboit", t, precision="single").stats["moment_bits"].value == 160
    assert [run("mboit", t, moments=m, precision="half-all").stats["moment_bits"].value
            for m in ("power4", "power6", "trig4")] == [80, 112, 144]
    # the reconstruction's work grows with the matrix: 3x3 real, 4x4 real, 5x5 complex
    assert mboit_reconstruct("power", 4) < mboit_reconstruct("power", 6) < mboit_reconstruct("trigonometric", 4)


def test_moment_reconstruction_roots_and_weights():
    """The kernel polynomial's roots and the Christoffel weights: the support points' weights sum to 1 (b_0
    normalised), Ferrari's roots agree with numpy's, and a degree drop (one fragment at depth 0.5, whose
    moments are as symmetric as the bias vector) is a root at infinity of weight 0, not a NaN."""
    zs = np.array([0.2, 0.5, 0.8], np.float32)
    for name, ms in M.CONFIGS.items():
        terms = M.moment_terms(M.warp_depth(zs), M.absorbance(np.full(3, 0.5, np.float32)), ms).sum(axis=0)
        query = M.warp_depth(np.array([0.1, 0.35, 0.65, 0.95], np.float32))
        b = M.normalised(np.full(4, terms[0], np.float32), np.tile(terms[1:], (4, 1)), ms, 5e-5)
        L, D = M._ldl(M._matrix(b, ms))
        if ms.kind == "power":
            x0 = query
            coef = M._kernel(L, D, x0).real.astype(np.float32)
            roots = M.quadratic_roots(coef) if ms.size == 3 else M.cubic_roots(coef)
        else:
            x0 = M._circle(M._phase(query))
            coef = M._kernel(L, D, x0).astype(np.complex64)
            roots = M.quartic_roots(coef)
            for i in range(4):
                ours = np.sort_complex(np.array([r[i] for r in roots]))
                assert np.abs(ours - np.sort_complex(np.roots(coef[i, ::-1].astype(complex)))).max() < 1e-4
        total = M._christoffel(L, D, x0) + sum(M._christoffel(L, D, r) for r in roots)
        assert np.allclose(total, 1.0, atol=1e-5), name
    one = M.moment_terms(M.warp_depth(np.array([0.5], np.float32)), M.absorbance(np.array([0.3], np.float32)),
                         M.CONFIGS["power6"])
    T, invalid = M.transmittance(one[:, 0], one[:, 1:], np.zeros(1, int), np.zeros(1, np.float32),
                                 M.CONFIGS["power6"], 5e-5, 0.25)
    assert not invalid.any() and np.isclose(T[0], 0.7 ** 0.25, atol=1e-4)


def test_mboit_composites_over_an_opaque_prepass():
    """An opaque fragment is drawn by the depth-tested pre-pass (rgba8); transparent fragments behind it are
    culled in both geometry passes, those in front composite over it; a pixel with one transparent
    fragment in front is exact (up to the opaque colour's rounding and b_0's)."""
    t = make_trace([0, 0, 0, 1, 1], [0, 0, 0, 0, 0], [0.5, 0.8, 0.2, 0.6, 0.3],
                   rgba=[[0.2, 0.6, 1.0, 1], [1, 0, 0, 0.5], [0, 1, 0, 0.4], [1, 1, 1, 1], [0, 0, 1, 0.5]],
                   opaque=[True, False, False, True, False], width=2, height=1, meta={"background": BG})
    res = run("mboit", t, **SINGLE)
    assert res.stats["culled_fragments"].value == 1
    opaque = rounder("rgba8")(np.array([0.2, 0.6, 1.0], np.float32))
    assert np.allclose(res.image[0, 0], 0.4 * np.array([0, 1, 0]) + 0.6 * opaque, atol=1e-5)
    assert np.allclose(res.image[0, 1], [0.5, 0.5, 1.0], atol=1e-5)
    n_t = 3                                                  # transparent fragments, each depth tested twice
    assert res.accesses["depth_buffer"] == {"depth_test": 2 + 2 * n_t}
    assert res.accesses["framebuffer"] == {"store": 2, "blend": 2}
    assert [p.name for p in res.passes] == ["opaque", "moments", "transmittance", "resolve"]
    assert res.accesses["zeroth_moment"]["blend"] == 2          # the culled fragment adds no moment
    blended = run("mboit", t, opaque="blend", **SINGLE)
    assert "depth_buffer" not in blended.footprint and blended.accesses["zeroth_moment"]["blend"] == 5


# ---------------------------------------------------------------------- timing
@pytest.mark.parametrize("name, params", [("mlab", {}), ("mlab", {"layers": 2, "hw": "rov"}), ("mboit", {}),
                                          ("mboit", {"moments": "trig4"})])
def test_every_timing_level_runs(name, params):
    trace = random_trace(1500, 8, seed=4)
    res = run(name, trace, **params)
    gpu = load_gpu("gtx280", ["runner.workers=1"])
    cycles = {}
    for level in ("analytic", "sampled", "full"):
        rec = run_timing(res, trace, level, gpu)[0]
        assert type(rec["cycles"]) is int and rec["cycles"] > 0
        assert [p["name"] for p in rec["passes"]] == [p.name for p in res.passes]
        cycles[level] = rec["cycles"]
    assert 0.5 < cycles["analytic"] / cycles["full"] < 2, cycles
    if name == "mlab" and params.get("hw") == "rov":
        assert rec.get("rmw_hazards", 0) == 0           # the interlock orders the read-modify-writes
