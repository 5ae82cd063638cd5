"""Seed 003 (Lin 2007): TFSS, R-buffer and Weight-Factor against the thesis's formulas and the reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import make_trace

from gpusim.errors import ConfigError, GpusimError
from gpusim.hw import thesis_timing
from gpusim.metrics import composite_exact, image_error
from gpusim.scene import load_scene, trace_scene
from gpusim.schemes import make_scheme
from gpusim.schemes.common.leading_zeros import colour_bits
from gpusim.schemes.common.weights import premultiply, unorm

FRAMES = (60, 120, 180, 240, 300, 360, 420, 480)
# seed 003 Table 4-1: (all fragments, transparent fragments, N_1..N_5)
TABLE_4_1 = {60: (2377518, 37684, [5812, 956, 6633, 2279, 189]), 120: (746943, 37594, [5723, 956, 6634, 2278, 189]),
             180: (516464, 40584, [8713, 956, 6634, 2278, 189]), 240: (488112, 88434, [32588, 12040, 7235, 2279, 189]),
             300: (623531, 60769, [26082, 2729, 6636, 2179, 121]), 360: (587617, 69768, [27421, 7094, 7006, 1569, 173]),
             420: (530258, 47877, [15728, 3290, 6770, 1296, 15]), 480: (605927, 135475, [95226, 8716, 6711, 671, 0])}
W, H = 640, 480


def run(name, trace, **params):
    return make_scheme(name, params).run(trace)


def on_8bit_grid(values):
    return np.rint(np.asarray(values) * 255) / 255


@pytest.fixture(scope="module", params=FRAMES)
def frame(request):
    scene, base = load_scene(f"thesis-frame{request.param}")
    return request.param, trace_scene(scene, base)


def test_bundled_frames_reproduce_table_4_1(frame):
    f, trace = frame
    total, transparent, hist = TABLE_4_1[f]
    assert (trace.width, trace.height) == (W, H) and len(trace) == total
    assert int((~trace.opaque).sum()) == transparent
    per_pixel = np.bincount(trace.pixel_ids()[~trace.opaque], minlength=W * H)
    assert np.bincount(per_pixel, minlength=6)[1:6].tolist() == hist


def test_footprints_and_accesses_equal_table_4_2_and_section_4_3_2(frame):
    """Every figure below is the thesis's formula evaluated by hand on the Table 4-1 row."""
    f, trace = frame
    _, _, hist = TABLE_4_1[f]
    N = {i + 1: c for i, c in enumerate(hist)}
    F = sum(i * c for i, c in N.items())                 # transparent fragments
    PX = sum(N.values())                                 # transparent pixels
    SA, L, D = 4, 3, 2

    tfss = run("tfss", trace, l_num=L)
    n_s = sum(c * math.ceil(i / L) for i, c in N.items())
    fp = tfss.footprint
    assert fp["t_buffer"] == L * 8 * n_s and fp["ssa_table"] == SA * W * H and fp["nsa_table"] == SA * n_s
    assert tfss.stats["storage_system_bytes"].value == (L * 8 + SA) * n_s + SA * W * H
    reads = tfss.plan.accesses({"fullscreen"})
    assert reads["t_buffer"]["load"] == F and reads["ssa_table"]["load"] == PX
    wf_compute = sum(c * (i * (i - 1) // 2 + 1) for i, c in N.items())
    assert thesis_timing(tfss)["cycles"] == F + PX + wf_compute

    wf = run("weight-factor", trace, d_avg=D)
    n_a = sum(c * (math.ceil(i / D) - 1) for i, c in N.items())
    assert wf.footprint["m_buffer"] == (W * H + n_a) * D * 8
    assert wf.footprint["pointer_memory"] == SA * (W * H + n_a)
    assert wf.plan.accesses({"fullscreen"})["m_buffer"]["load"] == F
    assert thesis_timing(wf)["cycles"] == F + wf_compute

    rb = run("r-buffer", trace)
    assert rb.footprint["r_buffer"] == F * 16 and rb.footprint["second_z_buffer"] == 4 * W * H
    assert rb.footprint["state_memory"] == 3 * W * H // 8
    f_r = sum(c * i * (i + 1) // 2 for i, c in N.items())
    # pass p reads every fragment still in the buffer: sum_p (F - sum_{j<p} sum_{i>=j} N_i)
    by_pass = sum(F - sum(sum(c for i, c in N.items() if i >= j) for j in range(1, p)) for p in range(1, 6))
    assert f_r == by_pass
    reads = rb.plan.accesses({"buffer"})
    assert reads["r_buffer"]["load"] == f_r and reads["second_z_buffer"]["depth_test"] == f_r
    assert reads["framebuffer"]["blend"] == F
    assert rb.stats["recirculation_passes"].value == max(i for i, c in N.items() if c)
    timing = thesis_timing(rb)
    assert timing["cycles"] == 2 * f_r + F + f_r and timing["compute_cycles"] == f_r
    # the thesis's ordering: TFSS far faster than the R-buffer, a little slower than WF; and smaller than WF
    assert thesis_timing(wf)["cycles"] < thesis_timing(tfss)["cycles"] < timing["cycles"]
    assert tfss.stats["storage_system_bytes"].value < wf.stats["storage_system_bytes"].value


@pytest.fixture
def grid_trace():
    rng = np.random.default_rng(3)
    n = 4000
    rgba = on_8bit_grid(rng.random((n, 4)))
    return make_trace(rng.integers(0, 16, n), rng.integers(0, 12, n), rng.random(n), rgba, rng.random(n) < 0.1,
                      width=16, height=12, meta={"background": [0.2, 0.4, 0.6]})


@pytest.mark.parametrize("name,params", [("tfss", {}), ("tfss", {"l_num": 1, "read_scan": "all"}),
                                         ("weight-factor", {}), ("weight-factor", {"d_avg": 5})])
def test_weight_factor_images_equal_the_exact_reference(name, params, grid_trace):
    res = run(name, grid_trace, **params)
    err = image_error(res.image, composite_exact(grid_trace))
    assert err["differing_pixels"] == 0 and err["max_abs"] < 1e-5, err


def test_rbuffer_is_exact_up_to_its_8bit_frame_buffer(grid_trace):
    res = run("r-buffer", grid_trace)
    layers = int(np.bincount(grid_trace.pixel_ids()).max())
    assert image_error(res.image, composite_exact(grid_trace))["max_abs"] <= layers * 0.5 / 255 + 1e-6
    assert image_error(run("r-buffer", grid_trace, colour_bits=16).image,
                       composite_exact(grid_trace))["max_abs"] < 1e-3


def test_opaque_fragments_stay_out_and_occluded_ones_are_discarded():
    # pixel 0: a transparent at 0.8 is stored, then an opaque at 0.5 arrives (it occludes the 0.8 after
    # the store); a transparent at 0.7 is culled on arrival; an opaque at 0.3; one visible at 0.1
    t = make_trace([0, 0, 0, 0, 0], [0] * 5, [0.8, 0.5, 0.7, 0.3, 0.1],
                   rgba=on_8bit_grid([[0, 0, 1, .5], [1, 0, 0, 1], [0, 1, 0, .5], [1, 1, 0, 1], [0, 1, 1, .4]]),
                   opaque=[False, True, False, True, False], width=2, height=1)
    for name in ("tfss", "weight-factor", "r-buffer"):
        res = run(name, t)
        assert res.stats["culled_at_arrival"].value == 1 and res.stats["occluded_after_store"].value == 1
        assert res.stats["stored_fragments"].value == 2
        assert res.lists.fragment.tolist() == [4]
        assert image_error(res.image, composite_exact(t))["max_abs"] < 1 / 255
    tfss = run("tfss", t)
    assert tfss.stats["sections"].value == 1 and tfss.footprint_used["ssa_table"] == 4   # pixel 1: no section
    rb = run("r-buffer", t)
    assert rb.stats["recirculation_passes"].value == 2     # pass 1 blends nothing: its target was occluded


def test_tfss_allocates_sections_only_for_transparent_pixels(random_trace):
    res = run("tfss", random_trace, l_num=2)
    pl_pixels = np.unique(random_trace.pixel_ids()[res.lists.fragment])
    assert res.stats["transparent_pixels"].value >= len(pl_pixels)
    stored = res.extras["read_per_pixel"]
    assert res.stats["sections"].value == int(np.ceil(stored / 2).sum())
    opaque = random_trace.subset(random_trace.opaque)
    none = run("tfss", opaque)
    assert none.footprint["t_buffer"] == 0 and none.footprint["nsa_table"] == 0
    assert "t_buffer" not in none.accesses and none.stats["sections"].value == 0
    one = run("tfss", random_trace, l_num=1)
    assert one.stats["sections"].value == one.stats["stored_fragments"].value
    assert one.footprint["t_buffer"] == 8 * one.stats["stored_fragments"].value


def test_no_z_buffer_without_opaque_fragments(random_trace):
    clear = random_trace.subset(~random_trace.opaque)
    for name in ("tfss", "weight-factor", "r-buffer"):
        res = run(name, clear)
        assert "z_buffer" not in res.footprint and "z_buffer" not in res.accesses
        assert res.stats["culled_at_arrival"].value == 0


def test_leading_zero_elimination_follows_figure_3_14():
    # R = 0000 1111, G = 0001 0010, B = 0010 0101, alpha = 0010 0000 (0.125)
    rgb = np.array([[0b00001111, 0b00010010, 0b00100101]])
    pm = premultiply(rgb, np.array([0b00100000]), 8)
    assert pm.tolist() == [[2, 2, 5]]                       # 3 significant bits at most, as in the figure
    assert colour_bits(pm, 8, "fixed").tolist() == [9]      # 3 bits per component
    assert colour_bits(pm, 8, "variable").tolist() == [7]   # 2 + 2 + 3
    assert colour_bits(rgb, 8, "fixed").tolist() == [18]    # without alpha: 2 leading zeros removed
    assert unorm(np.array([0.125]), 8).tolist() == [32]


def test_compressed_sections_count_what_does_not_fit(grid_trace):
    lze = run("tfss", grid_trace, leading_zero_elimination="fixed", l_num=3, section_bytes=20)
    assert "length_table" in lze.footprint and lze.stats["stored_bits_per_fragment"].value < 64
    assert lze.stats["section_breaks"].value > 0          # three fragments rarely fit 20 bytes
    assert image_error(lze.image, composite_exact(grid_trace))["max_abs"] < 2 / 255
    plain = run("tfss", grid_trace, l_num=3)
    assert lze.footprint["t_buffer"] == 20 * lze.stats["sections"].value
    assert plain.footprint["t_buffer"] == 24 * plain.stats["sections"].value
    # uniformly random colours and alphas keep most of their bits: the breaks cost more sections than the smaller
    # ones save, so here elimination costs memory (test_leading_zero_elimination_saves_memory_with_smaller_sections
    # has the thesis's case, where it saves)
    assert lze.stats["sections"].value > plain.stats["sections"].value
    assert lze.stats["storage_system_bytes"].value > plain.stats["storage_system_bytes"].value
    tiny = run("tfss", grid_trace, section_bytes=7)          # an 8-byte fragment never fits
    assert tiny.dropped_fragments == tiny.stats["unfit_fragments"].value == plain.stats["stored_fragments"].value
    assert tiny.stats["sections"].value == 0
    var = run("tfss", grid_trace, leading_zero_elimination="variable", l_num=3, section_bytes=20)
    assert var.stats["stored_bits_per_fragment"].value <= lze.stats["stored_bits_per_fragment"].value


def test_leading_zero_elimination_saves_memory_with_smaller_sections():
    """Section 4.3.1: with leading-0s elimination a section need not be L_num x 8 bytes. Dark, faint fragments
    (alpha 0.125, channels <= 0.2: premultiplied, each channel fits 3 bits; Figure 3-11's case) keep
    32 (depth) + 8 (alpha) + 3 x 3 = 49 bits, so three fit a 20-byte section (147 of 160 bits), where uncompressed
    fragments (64 bits) fit two. Pixel 0 holds 6 fragments, pixel 1 holds 3, on a 2x1 screen; S_A = 4 B.

    plain TFSS(3), 24-byte sections: 2 + 1 sections: T-buffer 72 B, NSA 12 B, SSA 8 B = 92 B
    with elimination, 20-byte sections: 3 sections: T-buffer 60 B, Length Table 3 x ceil(3 x 4 bits / 8) = 6 B,
                                        NSA 12 B, SSA 8 B = 86 B (6.5% less; the thesis finds about 5%)
    plain TFSS(3), 20-byte sections: 3 + 2 sections: T-buffer 100 B, NSA 20 B, SSA 8 B = 128 B
    """
    rng = np.random.default_rng(7)
    n = 9
    rgb = np.rint(rng.random((n, 3)) * 51) / 255                     # channels 0..51 of 255
    t = make_trace([0] * 6 + [1] * 3, [0] * n, rng.random(n), rgba=np.c_[rgb, np.full(n, 32 / 255)],
                   width=2, height=1)
    plain = run("tfss", t, l_num=3)
    lze = run("tfss", t, l_num=3, section_bytes=20, leading_zero_elimination="fixed")
    small = run("tfss", t, l_num=3, section_bytes=20)
    assert lze.stats["stored_bits_per_fragment"].value <= 49 and lze.stats["section_breaks"].value == 0
    assert [r.stats["sections"].value for r in (plain, lze, small)] == [3, 3, 5]
    assert [r.stats["storage_system_bytes"].value for r in (plain, lze, small)] == [92, 86, 128]
    assert lze.footprint["length_table"] == 6 and lze.footprint["t_buffer"] == 60
    assert lze.dropped_fragments == 0
    assert image_error(lze.image, composite_exact(t))["max_abs"] < 1 / 255      # premultiplied at 8 bits
    # the same scene in bright, opaque-ish colours (alpha 1: nothing to strip) breaks sections and costs more
    bright = make_trace([0] * 6 + [1] * 3, [0] * n, rng.random(n), rgba=np.c_[np.full((n, 3), 0.9), np.ones(n)],
                        width=2, height=1)
    assert (run("tfss", bright, l_num=3, section_bytes=20, leading_zero_elimination="fixed")
            .stats["storage_system_bytes"].value > run("tfss", bright, l_num=3).stats["storage_system_bytes"].value)


def test_equal_depths_eq4_brightens_and_arrival_matches_reference():
    t = make_trace([0, 0], [0, 0], [0.5, 0.5], rgba=on_8bit_grid([[1, 0, 0, .6], [0, 1, 0, .6]]), width=1, height=1)
    ref = composite_exact(t)
    assert image_error(run("tfss", t).image, ref)["max_abs"] < 1e-5
    eq4 = run("weight-factor", t, ties="eq4").image
    assert eq4[0, 0, 1] > ref[0, 0, 1] + 0.2          # neither layer attenuates the other
    rb = run("r-buffer", t)
    assert rb.stats["tie_blends"].value == 1 and rb.stats["recirculation_passes"].value == 1


def test_thesis_fidelity_and_parameter_errors(random_trace):
    with pytest.raises(GpusimError, match="models only r-buffer, tfss, weight-factor"):
        thesis_timing(run("freepipe-abuffer", random_trace))
    with pytest.raises(ConfigError, match="fragment_bytes 4 cannot hold"):
        make_scheme("tfss", {"fragment_bytes": 4})
    with pytest.raises(ConfigError, match="leading_zero_elimination: 'lz4' is not a valid choice"):
        make_scheme("tfss", {"leading_zero_elimination": "lz4"})


def test_histogram_scene_rejects_impossible_counts():
    with pytest.raises(ConfigError, match="names 400,000 pixels but the screen has 307,200"):
        load_scene("thesis-frame60", ["transparent_per_pixel=[400000]"])
    with pytest.raises(ConfigError, match="fewer than the transparent fragments"):
        load_scene("thesis-frame60", ["fragments=1000"])


@pytest.mark.parametrize("scheme", ["tfss", "weight-factor", "r-buffer"])
def test_the_pipeline_buffers_count_only_pixels_they_hold(scheme):
    """The z-buffer holds a depth only where an opaque fragment was written: a pixel of transparent fragments
    alone uses no z-buffer entry (it once counted as holding one), and the frame buffer holds the pixels with
    an opaque or a blended fragment."""
    t = make_trace([0, 0, 1, 1, 2], [0] * 5, [0.5, 0.6, 0.4, 0.7, 0.3], opaque=[False, False, True, False, False],
                   width=4, height=1)
    used = make_scheme(scheme).run(t).footprint_used
    assert used["z_buffer"] == 4                                     # pixel 1's opaque depth only
    assert used["framebuffer"] <= 3 * make_scheme(scheme).run(t).footprint["framebuffer"] // 4
