"""Scenes: TOML descriptions of a camera and objects, turned into fragment traces."""

from gpusim.scene.load import builtin_scenes, load_scene, resolve_scene, trace_scene
from gpusim.scene.model import OBJECT_KINDS, Scene

__all__ = ["OBJECT_KINDS", "Scene", "builtin_scenes", "load_scene", "resolve_scene", "trace_scene"]
