"""The exact reference compositor and the image error metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import make_trace
from gpusim.metrics import composite_exact, image_error


def brute_force(trace, bg):
    """Per-pixel Python reference: sort by (depth, submission index), composite in float64."""
    img = np.tile(np.asarray(bg, float), (trace.height, trace.width, 1))
    pix = trace.pixel_ids()
    for p in np.unique(pix):
        idx = np.flatnonzero(pix == p)
        idx = sorted(idx, key=lambda i: (float(trace.z[i]), i))
        col, trans = np.zeros(3), 1.0
        for i in idx:
            a = 1.0 if trace.opaque[i] else float(trace.rgba[i, 3])
            col += trans * a * trace.rgba[i, :3].astype(float)
            trans *= 1.0 - a
        img[p // trace.width, p % trace.width] = col + trans * np.asarray(bg, float)
    return img


def test_matches_brute_force_on_random_trace(random_trace):
    np.testing.assert_allclose(composite_exact(random_trace), brute_force(random_trace, [0.2, 0.3, 0.4]),
                               rtol=0, atol=1e-12)


def test_order_independent_of_submission_for_distinct_depths(random_trace):
    perm = np.random.default_rng(1).permutation(len(random_trace))
    shuffled = random_trace.subset(perm)
    np.testing.assert_allclose(composite_exact(shuffled), composite_exact(random_trace), atol=1e-12)


def test_equal_depths_resolve_in_submission_order():
    red, green = [1, 0, 0, 0.5], [0, 1, 0, 0.5]
    first_red = composite_exact(make_trace([0, 0], [0, 0], [0.5, 0.5], [red, green]), [0, 0, 0])
    first_green = composite_exact(make_trace([0, 0], [0, 0], [0.5, 0.5], [green, red]), [0, 0, 0])
    np.testing.assert_allclose(first_red[0, 0], [0.5, 0.25, 0.0])
    np.testing.assert_allclose(first_green[0, 0], [0.25, 0.5, 0.0])


def test_opaque_fragment_hides_everything_behind_it():
    t = make_trace([1, 1, 1], [1, 1, 1], [0.9, 0.3, 0.5],
                   [[0, 0, 1, 0.5], [1, 0, 0, 0.2], [0, 1, 0, 0.7]], opaque=[False, False, True])
    # red (a=0.2) in front of opaque green; blue behind is hidden; opaque counts as a=1
    np.testing.assert_allclose(composite_exact(t, [1, 1, 1])[1, 1], [0.2, 0.8, 0.0])


def test_alpha_zero_and_one():
    t = make_trace([0, 0, 0], [0, 0, 0], [0.1, 0.2, 0.3], [[1, 0, 0, 0.0], [0, 1, 0, 1.0], [0, 0, 1, 1.0]])
    np.testing.assert_allclose(composite_exact(t, [1, 1, 1])[0, 0], [0, 1, 0])


def test_thousands_of_layers_stay_finite_and_exact():
    n = 20000
    rng = np.random.default_rng(9)
    z = rng.random(n)
    t = make_trace(np.zeros(n), np.zeros(n), z, np.tile([0.5, 0.25, 1.0, 0.001], (n, 1)), width=2, height=1)
    got = composite_exact(t, [0, 0, 0])
    trans = (1 - np.float32(0.001).astype(float)) ** n
    expect = np.array([0.5, 0.25, 1.0]) * (1 - trans)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got[0, 0], expect, rtol=1e-9)
    np.testing.assert_allclose(got[0, 1], [0, 0, 0])


def test_image_error_metrics():
    ref = np.zeros((4, 5, 3))
    img = ref.copy()
    assert image_error(img, ref) == {"rmse": 0.0, "psnr": math.inf, "differing_pixels": 0,
                                     "differing_share": 0.0, "max_abs": 0.0}
    img[0, 0] = [0.5, 0, 0]
    img[1, 1, 2] = 1.0 / 255.0  # exactly one 8-bit step: not "differing"
    err = image_error(img, ref)
    assert err["differing_pixels"] == 1 and err["differing_share"] == pytest.approx(1 / 20)
    assert err["rmse"] == pytest.approx(np.sqrt((0.25 + (1 / 255) ** 2) / 60))
    assert err["psnr"] == pytest.approx(20 * np.log10(1 / err["rmse"]))
    with pytest.raises(ValueError):
        image_error(np.zeros((2, 2, 3)), ref)
