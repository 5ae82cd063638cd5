"""Finding, loading and tracing scenes.

A scene argument is a scene TOML file, a mesh file (OBJ, PLY, OFF, STL), or the
name of a built-in scene: ``configs/scenes/<name>.toml`` in the gpusim source
tree, or in a folder named by the ``GPUSIM_SCENES`` environment variable.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from gpusim import __version__
from gpusim.config import build, build_overridden, load_toml, to_dict
from gpusim.errors import ConfigError
from gpusim.raster import rasterize
from gpusim.scene.build import scene_triangles
from gpusim.scene.histogram import HistogramScene, histogram_trace
from gpusim.scene.model import Scene
from gpusim.trace import FragmentTrace

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")


def scene_dirs() -> list[Path]:
    """Folders searched for built-in scene names, in order."""
    dirs = []
    if os.environ.get("GPUSIM_SCENES"):
        dirs.append(Path(os.environ["GPUSIM_SCENES"]))
    dirs.append(Path(__file__).resolve().parents[2] / "configs" / "scenes")
    return [d for d in dirs if d.is_dir()]


def builtin_scenes() -> list[str]:
    """Names of the built-in scenes."""
    return sorted({p.stem for d in scene_dirs() for p in d.glob("*.toml")})


def resolve_scene(arg: str) -> Path:
    """The file a scene argument names; unknown names fail with the list of built-ins."""
    path = Path(arg)
    if path.is_file():
        return path
    if path.suffix or os.sep in arg:
        raise ConfigError(f"{arg}: no such scene or mesh file; check the path")
    for d in scene_dirs():
        candidate = d / f"{arg}.toml"
        if candidate.is_file():
            return candidate
    raise ConfigError(f"unknown scene '{arg}' (built-in scenes: {', '.join(builtin_scenes()) or 'none'}); "
                      "or give a .toml scene file or a mesh file")


def mesh_scene_table(mesh: Path, alpha: float) -> dict:
    """A scene table that frames one normalised mesh file."""
    return {"name": mesh.stem, "description": f"mesh file {mesh.name}",
            "camera": {"eye": [0.0, 0.3, 2.8], "target": [0.0, 0.0, 0.0], "near": 0.5, "far": 10.0},
            "objects": [{"kind": "mesh", "path": str(mesh.resolve()), "alpha": alpha,
                         "color": [0.85, 0.75, 0.6]}]}


def load_scene(arg: str, overrides: Iterable[str] = (), alpha: float | None = None,
               size: tuple[int, int] | None = None) -> tuple[Scene | HistogramScene, Path]:
    """Load a scene (file, mesh or built-in name) with ``--set`` overrides and the ``--size`` (width,
    height); returns it and its folder. A problem an override brings names the override, not the file.

    A file with ``kind = "histogram"`` at its top level is a histogram scene
    (gpusim.scene.histogram); any other is a geometric :class:`Scene`.
    """
    path = resolve_scene(arg)
    if path.suffix.lower() in MESH_SUFFIXES:
        a = 0.5 if alpha is None else alpha
        if not 0.0 <= a <= 1.0:
            raise ConfigError(f"--alpha {a}: must lie in [0, 1]")
        table = mesh_scene_table(path, a)
    elif path.suffix.lower() == ".toml":
        if alpha is not None:
            raise ConfigError("--alpha applies to mesh files only; set objects.N.alpha in a scene file")
        table = load_toml(path)
    else:
        csv = ("; a CSV fragment list is imported with 'gpusim trace --from-csv FILE --size WxH -o OUT.npz'"
               if path.suffix.lower() == ".csv" else "")
        raise ConfigError(f"{path}: unsupported scene file type '{path.suffix}' "
                          f"(valid: .toml, {', '.join(MESH_SUFFIXES)}){csv}")
    overrides = list(overrides)
    labels = [f"--set {text}" for text in overrides]
    if size is not None:
        overrides += [f"screen.width={size[0]}", f"screen.height={size[1]}"]
        labels += [f"--size {size[0]}x{size[1]}"] * 2
    scene = build_overridden(lambda data, where: build(HistogramScene if data.get("kind") == "histogram" else Scene,
                                                       data, where), table, str(path), overrides, labels=labels)
    return scene, path.parent


def trace_scene(scene: Scene | HistogramScene, base_dir: Path, where: str = "scene",
                progress: bool | None = None) -> FragmentTrace:
    """Rasterize a scene into a fragment trace whose metadata records the resolved scene."""
    if isinstance(scene, HistogramScene):
        return histogram_trace(scene)
    batch = scene_triangles(scene, base_dir, where)
    meta = {"scene": scene.name, "generator": "gpusim trace", "gpusim_version": __version__,
            "background": list(scene.screen.background), "primitives": len(batch),
            "scene_config": to_dict(scene)}
    return rasterize(batch, scene.screen.width, scene.screen.height, scene.raster.cull,
                     meta=meta, progress=progress)
