"""The scene's fragment shader (gpusim.shaders): its counts, where schemes run it, what it costs in time.

Uses the tiny trace of test_scheme_alu: a 4x2 screen, pixel 0 with fragments
0, 1, 3, pixel 1 with fragments 2, 4, pixel 6 with fragment 5 (and, opaque,
fragment 6 on pixel 1, submitted last).
"""

from __future__ import annotations

import typing

import numpy as np
import pytest
from conftest import make_trace
from test_scheme_alu import computes, tiny

from gpusim.errors import GpusimError
from gpusim.hw import load_gpu
from gpusim.opplan import Pass
from gpusim.replay import run_timing
from gpusim.scene.load import load_scene, trace_scene
from gpusim.schemes import make_scheme, scheme_names
from gpusim.shaders import FRAGMENT_SHADERS, ShaderName, fragment_shader, trace_fragment_shader

LIT = FRAGMENT_SHADERS["lucid-simple"]


def lit(trace):
    """``trace`` with its scene declaring LucidRaster's simple material."""
    trace.meta["scene_config"] = {"fragment_shader": "lucid-simple"}
    return trace


def shading_groups(name, trace, **params):
    """The compute groups the shader adds to scheme ``name``'s plan on ``trace`` (the shaded plan less the
    plain one's groups, in order), as computes() gives them, and the shaded result."""
    plain = make_scheme(name, params).run(trace)
    res = make_scheme(name, params).run(lit(trace))
    added, rest = [], list(plain.plan.groups)
    def same(a, b):
        return ((a.op, a.structure, a.dep, len(a.thread)) == (b.op, b.structure, b.dep, len(b.thread))
                and np.array_equal(np.asarray(a.instructions), np.asarray(b.instructions)))
    for g in res.plan.groups:
        if rest and same(g, rest[0]):
            rest.pop(0)
        else:
            added.append(g)
    assert not rest
    plan = type(res.plan)(res.plan.passes, res.plan.structures, added)
    return computes(type("R", (), {"plan": plan})), res


def test_lucid_simple_counts_its_fragment_stage_by_hand():
    # flag test 2, position 3 + derivatives 12 + cross 6 + normalize 7, colour 4 + 4, texture flag 2, light 5,
    # finalShading 24 + 9 + 6 + 21, alpha move 1
    assert (LIT.colour, LIT.alpha) == (106, 4)
    assert LIT.instructions("colour") == 106 and LIT.instructions("alpha") == 4 and LIT.instructions("none") == 0
    assert FRAGMENT_SHADERS["none"].instructions("colour") == 0
    assert set(typing.get_args(ShaderName)) == set(FRAGMENT_SHADERS)


def test_unknown_shaders_and_shadings_are_refused_naming_the_valid_ones():
    with pytest.raises(ValueError, match="unknown fragment shader 'phong' \\(valid: none, lucid-simple\\)"):
        fragment_shader("phong")
    with pytest.raises(ValueError, match="valid: colour, alpha, none"):
        LIT.instructions("depth")
    with pytest.raises(ValueError, match="bad pass"):
        Pass("p", "geometry", "fragment", shading="depth")


def test_a_trace_without_a_declared_shader_runs_none():
    assert trace_fragment_shader({}).name == "none"
    assert trace_fragment_shader({"scene_config": {"name": "x"}}).name == "none"
    assert trace_fragment_shader({"scene_config": {"fragment_shader": "lucid-simple"}}) is LIT
    with pytest.raises(ValueError, match="scene_config.fragment_shader: unknown fragment shader 'phong'"):
        trace_fragment_shader({"scene_config": {"fragment_shader": "phong"}})


def test_alpha_blending_shades_every_fragment_of_each_pass_first():
    got, res = shading_groups("alpha-blend", tiny())
    assert got == [(0, {f: 106 for f in range(6)})]
    assert res.plan.groups[0].is_compute and res.plan.groups[1].op == "blend"
    # with an opaque fragment: its pre-pass shades it; the transparent pass shades what it depth-tests
    got, _ = shading_groups("alpha-blend", tiny(opaque=True))
    assert got == [(0, {6: 106}), (1, {f: 106 for f in range(6)})]


def test_moment_oit_needs_only_alpha_in_its_moment_pass():
    assert shading_groups("mboit", tiny())[0] == [(0, {f: 4 for f in range(6)}), (1, {f: 106 for f in range(6)})]


def test_peeling_shades_in_every_pass_and_dual_peeling_not_in_its_depth_only_first():
    got, res = shading_groups("depth-peeling", tiny())
    assert got == [(p, {f: 106 for f in range(6)}) for p in (0, 2, 4)]
    assert res.plan.groups[0].seq_pass.tolist() == [0, 2, 4]     # one group across the passes
    assert [p for p, _ in shading_groups("dual-depth-peeling", tiny())[0]] == [1, 2]


def test_freepipe_mdts_shades_its_capture_only_when_it_packs_the_colour():
    assert [p for p, _ in shading_groups("freepipe-mdts", tiny())[0]] == [2]     # depth capture, then colour
    assert [p for p, _ in shading_groups("freepipe-mdts", tiny(), packing=True, alpha=0.5)[0]] == [1]


def test_the_kbuffer_shades_behind_its_scoreboard_and_not_for_z_only_entries():
    got, res = shading_groups("kbuffer", tiny(), hw="scoreboard")
    assert got == [(1, {f: 106 for f in range(6)})]
    ops = [g.op for g in res.plan.groups]
    assert ops[ops.index("scoreboard") + 1] == "compute" and res.plan.groups[ops.index("scoreboard") + 1].dep is False
    assert shading_groups("kbuffer", tiny(), entry="z", k=4)[0] == []
    assert shading_groups("multipass-kbuffer", tiny(), entry="z", k=4)[0] == []
    # the stencil-routed A-buffer's overflow pass only tests stencil: its capture alone shades
    assert [p for p, _ in shading_groups("stencil-routed-abuffer", tiny())[0]] == [1]


#: schemes whose geometry passes need no colour: the bucket methods keep depths only (seed 000's translucency)
DEPTH_ONLY = {"bucket-depth-peeling", "adaptive-bucket-depth-peeling"}


@pytest.mark.parametrize("name", scheme_names())
def test_every_scheme_keeps_its_access_counts_and_only_lucidraster_shades_by_itself(name):
    params = {"alpha": 0.5} if name == "freepipe-mdts" else {}
    plain = make_scheme(name, params).run(tiny())
    shaded = make_scheme(name, params).run(lit(tiny()))
    assert shaded.accesses == plain.accesses
    added = len(shaded.plan.groups) - len(plain.plan.groups)
    assert [(g.op, g.structure) for g in shaded.plan.groups[added:]] == [(g.op, g.structure)
                                                                        for g in plain.plan.groups]
    if name == "lucidraster" or name in DEPTH_ONLY:   # LucidRaster's shadeSample always lights (alu.SHADE_SAMPLE)
        assert added == 0
    else:
        assert added >= 1 and all(g.is_compute and not g.dep for g in shaded.plan.groups[:added])


@pytest.mark.parametrize("level", ["analytic", "full"])
def test_the_shader_costs_its_warps_issue_cycles_where_the_sms_bound_the_pass(level):
    # 64x64 pixels, 4 layers each, in triangles of 2 fragments side by side: each triangle is half a 2x2 quad, so
    # its 4 shader lanes hold 2 helper lanes, and the pass has 4 x 8192 / 32 = 1024 warps. One SM of 32 lanes at
    # 1 instruction a cycle: the shader's 106 instructions a warp add 1024 x 106 = 108,544 issue cycles to a pass
    # bound by the SM
    n = 64 * 64 * 4
    rng = np.random.default_rng(1)
    xs, ys = np.tile(np.arange(64 * 64) % 64, 4), np.tile(np.arange(64 * 64) // 64, 4)
    trace = make_trace(xs, ys, rng.random(n), width=64, height=64, prim=np.repeat(np.arange(n // 2), 2))
    gpu = load_gpu("gtx280", ["core.sms=1", "core.lanes_per_sm=32", "core.schedulers=1", "core.warps_per_sm=32",
                              "rop.units=64", "raster.quads_per_cycle=64", "raster.triangles_per_cycle=64"])
    cycles = {}
    for shaded in (False, True):
        t = lit(trace) if shaded else trace
        res = make_scheme("alpha-blend").run(t)
        cycles[shaded] = run_timing(res, t, level, gpu)[0]["cycles"]
    extra = cycles[True] - cycles[False]
    assert extra == pytest.approx(1024 * gpu.core.alu_cycles(106), rel=0.01)


def test_a_scene_declares_its_shader_and_the_trace_records_it(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('name = "s"\nfragment_shader = "lucid-simple"\n[screen]\nwidth = 16\nheight = 16\n'
                     '[[objects]]\nkind = "sphere"\n')
    loaded, base = load_scene(str(scene))
    assert trace_fragment_shader(trace_scene(loaded, base).meta) is LIT
    scene.write_text('name = "s"\nfragment_shader = "phong"\n[[objects]]\nkind = "sphere"\n')
    with pytest.raises(GpusimError, match="fragment_shader: 'phong' is not a valid choice"):
        load_scene(str(scene))


def test_a_run_timed_with_another_shader_is_another_run():
    from gpusim.experiment.runner import trace_sha256
    plain = tiny()
    assert trace_sha256(lit(tiny())) != trace_sha256(plain)
    none = tiny()
    none.meta["scene_config"] = {"fragment_shader": "none"}
    assert trace_sha256(none) == trace_sha256(plain)          # traces that declare none keep their hash


def test_mlab_shades_before_its_interlock():
    got, res = shading_groups("mlab", tiny(), hw="rov", layers=2)
    assert got == [(1, {f: 106 for f in range(6)})]
    ops = [g.op for g in res.plan.groups]
    shader = next(i for i, g in enumerate(res.plan.groups) if g.is_compute and int(np.max(g.instructions)) == 106)
    assert shader < ops.index("scoreboard")
