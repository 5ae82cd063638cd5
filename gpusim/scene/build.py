"""Turning a :class:`~gpusim.scene.model.Scene` into clip-space triangles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpusim.raster.batch import TriangleBatch
from gpusim.scene import geometry
from gpusim.scene.camera import look_at, model_matrix, perspective
from gpusim.scene.model import Mesh, Scene
from gpusim.scene.subdivide import subdivide


def scene_triangles(scene: Scene, base_dir: Path = Path("."), where: str = "scene") -> TriangleBatch:
    """All objects' triangles in submission order, in clip space, with shaded vertex colours."""
    cam = scene.camera
    aspect = scene.screen.width / scene.screen.height
    view_proj = perspective(cam.fov_y_deg, aspect, cam.near, cam.far) @ look_at(cam.eye, cam.target, cam.up)
    light = np.asarray(scene.lighting.direction, dtype=np.float64)
    light = light / (np.linalg.norm(light) or 1.0)
    batches, world = [], []
    for i, obj in enumerate(scene.objects):
        if isinstance(obj, Mesh):
            data = geometry.mesh_file(obj, base_dir, f"{where}: objects[{i}]")
        else:
            data = geometry.GENERATORS[obj.kind](obj)
        model = model_matrix(obj.translate, obj.rotate_deg, obj.scale)
        homo = np.concatenate([data.vertices, np.ones((len(data.vertices), 1))], axis=1)
        clip = homo @ (view_proj @ model).T
        if data.rgba is not None:
            rgba = data.rgba.copy()
        else:
            rgba = np.tile([*obj.color, obj.alpha], (len(data.vertices), 1))
        if obj.shading == "lambert":
            normal_matrix = np.linalg.inv(model[:3, :3]).T
            n = data.normals @ normal_matrix.T
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
            amb = scene.lighting.ambient
            rgba[:, :3] *= (amb + (1.0 - amb) * np.abs(n @ light))[:, None]  # two-sided
        if obj.opaque:
            rgba[:, 3] = 1.0
        batches.append(TriangleBatch(clip[data.faces], rgba[data.faces],
                                     np.full(len(data.faces), obj.opaque)))
        if scene.subdivide_budget > 1.0:
            world.append((homo @ model.T)[:, :3][data.faces])
    batch = TriangleBatch.concat(batches)
    if scene.subdivide_budget > 1.0:
        batch = subdivided(batch, np.concatenate(world), scene.subdivide_budget)
    return batch


def subdivided(batch: TriangleBatch, world: np.ndarray, budget: float) -> TriangleBatch:
    """``batch`` split by the seed 004 scheme (gpusim.scene.subdivide) to ``budget`` times its triangles,
    lengths and aspect ratios measured on the (T, 3, 3) ``world`` corners. A new vertex's clip position and
    colour are interpolated along the split edge, which leaves the surface, its depth and its perspective-
    correct colours as they were; each triangle's pieces take its place in submission order."""
    carried = np.concatenate([batch.clip, batch.rgba], axis=2)
    _, carried, parent = subdivide(world, carried, budget)
    return TriangleBatch(carried[..., :4], carried[..., 4:], batch.opaque[parent])
