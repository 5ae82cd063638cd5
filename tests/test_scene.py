"""Scene files: typed loading, overrides, bad keys and values, procedural geometry, built-ins."""

from __future__ import annotations

import numpy as np
import pytest

from gpusim.config import apply_overrides, build, describe, to_dict
from gpusim.errors import ConfigError
from gpusim.scene import builtin_scenes, load_scene, trace_scene
from gpusim.scene import geometry
from gpusim.scene.model import Box, LayeredQuads, Scene, Sphere


def write(tmp_path, text):
    path = tmp_path / "s.toml"
    path.write_text(text)
    return str(path)


MINIMAL = """
name = "t"
[screen]
width = 32
height = 24
[[objects]]
kind = "sphere"
"""


def test_minimal_scene_gets_typed_defaults(tmp_path):
    scene, _ = load_scene(write(tmp_path, MINIMAL))
    assert scene.screen.width == 32 and scene.camera.fov_y_deg == 45.0
    assert isinstance(scene.objects[0], Sphere) and scene.objects[0].radius == 1.0


@pytest.mark.parametrize("text, expect", [
    (MINIMAL + "bogus = 1\n", "objects.0.bogus: unknown key (valid: kind, translate"),
    (MINIMAL.replace("[screen]", "[screen]\nwidht = 3"), "screen.widht: unknown key (valid: width, height, background)"),
    (MINIMAL.replace('"sphere"', '"teapot"'), "objects.0.kind: 'teapot' is not a known kind (valid: box, layered-quads"),
    (MINIMAL.replace("width = 32", "width = 0"), "screen.width: must be >= 1 px, got 0"),
    (MINIMAL.replace("width = 32", 'width = "wide"'), "screen.width: expected an integer"),
    (MINIMAL + "radius = -1.0\n", "objects.0.radius: must be > 0.0 scene units"),
    (MINIMAL + "alpha = 1.5\n", "objects.0.alpha: must be <= 1.0"),
    (MINIMAL + "color = [1, 2, 0]\n", "color components must lie in [0, 1]"),
    (MINIMAL + "[camera]\nnear = 5.0\nfar = 1.0\n", "far (1.0) must be greater than near (5.0)"),
    ('name = "t"\n', "a scene needs at least one [[objects]] table"),
    ("name = \n", "invalid TOML"),
])
def test_bad_scene_fails_naming_key_and_file(tmp_path, text, expect):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as exc:
        load_scene(path)
    assert expect in str(exc.value) and path in str(exc.value) and "\n" not in str(exc.value)


def test_overrides_set_nested_keys_and_list_entries(tmp_path):
    scene, _ = load_scene(write(tmp_path, MINIMAL), ["camera.fov_y_deg=60", "objects.0.alpha=0.25",
                                                     "screen.background=[0, 0, 0]"])
    assert scene.camera.fov_y_deg == 60.0 and scene.objects[0].alpha == 0.25
    assert scene.screen.background == (0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match="not an index into a list of 1 entries"):
        load_scene(write(tmp_path, MINIMAL), ["objects.3.alpha=0.1"])
    with pytest.raises(ConfigError, match="unknown key"):
        load_scene(write(tmp_path, MINIMAL), ["camera.zoom=2"])
    with pytest.raises(ConfigError, match="expected KEY=VALUE"):
        apply_overrides({}, ["camera.fov"])


def test_resolved_config_exports_and_rebuilds(tmp_path):
    scene, _ = load_scene("default")
    again = build(Scene, to_dict(scene), "exported")
    assert again == scene
    rows = {r["name"]: r for r in describe(Sphere)}
    assert rows["radius"]["unit"] == "scene units" and rows["radius"]["doc"]


def test_unknown_builtin_lists_the_valid_names():
    with pytest.raises(ConfigError) as exc:
        load_scene("no-such-scene")
    assert "built-in scenes: " in str(exc.value) and "default" in str(exc.value)
    assert {"default", "bunny", "stress-layers", "coplanar", "alpha-extremes", "slivers"} <= set(builtin_scenes())


def test_missing_mesh_file_gives_the_install_hint(tmp_path):
    text = MINIMAL.replace('kind = "sphere"', 'kind = "mesh"\npath = "nope.obj"\ninstall_hint = "get it"')
    with pytest.raises(ConfigError, match="nope.obj not found; get it"):
        trace_scene(*load_scene(write(tmp_path, text)))


def test_mesh_file_as_scene(tmp_path):
    import trimesh
    path = tmp_path / "ico.ply"
    trimesh.creation.icosphere(subdivisions=2).export(path)
    scene, base = load_scene(str(path), ["screen.width=64", "screen.height=64"], alpha=0.3)
    t = trace_scene(scene, base, progress=False)
    assert len(t) > 0 and t.depth_complexity().max() == 2 and np.allclose(t.rgba[:, 3], 0.3, atol=1e-6)
    with pytest.raises(ConfigError, match="--alpha 2.0: must lie in"):
        load_scene(str(path), alpha=2.0)


@pytest.mark.parametrize("spec", [Sphere(kind="sphere", segments=7, rings=5), Box(kind="box")])
def test_closed_meshes_wind_outwards(spec):
    mesh = geometry.GENERATORS[spec.kind](spec)
    tri = mesh.vertices[mesh.faces]
    signed_volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert signed_volume > 0
    areas = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert areas.min() > 0


def test_layered_quads_order_and_colours_belong_to_layers():
    spec = LayeredQuads(kind="layered-quads", layers=5, spacing=0.5, order="random", seed=4,
                        colors=((1, 0, 0), (0, 1, 0)), alphas=(0.1, 0.9))
    mesh = geometry.layered_quads(spec)
    z = mesh.vertices[::4, 2]
    layer = np.rint(-z / 0.5).astype(int)
    assert sorted(layer) == list(range(5)) and list(layer) != list(range(5))
    np.testing.assert_allclose(mesh.rgba[::4, 3], np.where(layer % 2 == 0, 0.1, 0.9))


def test_default_scene_has_real_multi_fragment_load():
    t = trace_scene(*load_scene("default", ["screen.width=128", "screen.height=128"]), progress=False)
    dc = t.depth_complexity()
    assert dc.max() > 8 and (~t.opaque).sum() > 0 and t.opaque.sum() > 0


def test_stress_scenes_have_their_extremes():
    layers = trace_scene(*load_scene("stress-layers"), progress=False)
    dc = layers.depth_complexity()
    assert dc.max() >= 4000 and (dc == 1).sum() > 1000
    coplanar = trace_scene(*load_scene("coplanar"), progress=False)
    assert coplanar.depth_complexity().max() == 16
    pix = coplanar.pixel_ids()
    first = pix == pix[0]
    assert np.unique(coplanar.z[first]).size == 1          # equal depths at one pixel
    extremes = trace_scene(*load_scene("alpha-extremes"), progress=False)
    assert {0.0, 1.0} <= set(np.unique(extremes.rgba[:, 3]).tolist()) and extremes.opaque.any()
    slivers = trace_scene(*load_scene("slivers"), progress=False)
    assert slivers.depth_complexity().max() == 2           # the fan never covers a pixel twice


def test_tracing_is_deterministic():
    a = trace_scene(*load_scene("default", ["screen.width=96", "screen.height=64"]), progress=False)
    b = trace_scene(*load_scene("default", ["screen.width=96", "screen.height=64"]), progress=False)
    for name in ("x", "y", "z", "rgba", "prim", "opaque"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
