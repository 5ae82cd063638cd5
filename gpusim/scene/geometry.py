"""Object-space triangle meshes for the procedural object kinds and mesh files.

Each generator returns a :class:`MeshData`; faces wind counter-clockwise when
seen from outside (OpenGL front faces).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpusim.errors import ConfigError
from gpusim.scene import model as m
from gpusim.scene.tetmesh import tet_ventricle


@dataclass
class MeshData:
    """Vertices (V,3) float64, faces (F,3) int64, vertex normals (V,3), optional vertex RGBA (V,4)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    rgba: np.ndarray | None = None


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def sphere(spec: m.Sphere) -> MeshData:
    theta = np.linspace(0.0, np.pi, spec.rings + 1)            # from +y pole to -y pole
    phi = np.linspace(0.0, 2.0 * np.pi, spec.segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    cols = spec.segments + 1
    r, s = np.meshgrid(np.arange(spec.rings), np.arange(spec.segments), indexing="ij")
    a = (r * cols + s).ravel()
    b, c, d = a + cols, a + 1, a + cols + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    # drop the zero-area triangles at the poles
    top, bottom = r.ravel() == 0, r.ravel() == spec.rings - 1
    keep = np.concatenate([~bottom, ~top])
    return MeshData(normals * spec.radius, faces[keep].astype(np.int64), normals)


def box(spec: m.Box) -> MeshData:
    half = np.asarray(spec.size) / 2.0
    verts, normals, faces = [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            corners = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis] = sign * half[axis]
                p[u_axis] = du * half[u_axis]
                p[v_axis] = dv * half[v_axis]
                corners.append(p)
            base = len(verts)
            quad = [0, 1, 2, 3] if sign > 0 else [0, 3, 2, 1]
            verts.extend(corners)
            normals.extend([n] * 4)
            faces.append([base + quad[0], base + quad[1], base + quad[2]])
            faces.append([base + quad[0], base + quad[2], base + quad[3]])
    return MeshData(np.array(verts), np.array(faces, dtype=np.int64), np.array(normals))


def _grid(size: tuple[float, float], nx: int, ny: int, z: float = 0.0):
    xs = np.linspace(-size[0] / 2, size[0] / 2, nx + 1)
    ys = np.linspace(-size[1] / 2, size[1] / 2, ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="xy")
    verts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    a = (j * (nx + 1) + i).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    # interleave so each quad's two triangles are consecutive in submission order
    faces = faces.reshape(2, -1, 3).transpose(1, 0, 2).reshape(-1, 3)
    return verts, faces


def quad_grid(spec: m.QuadGrid) -> MeshData:
    verts, faces = _grid(spec.size, *spec.divisions)
    normals = np.tile([0.0, 0.0, 1.0], (len(verts), 1))
    return MeshData(verts, faces, normals)


def layered_quads(spec: m.LayeredQuads) -> MeshData:
    n = spec.layers
    depth = np.arange(n) * spec.spacing          # layer i sits at z = -i * spacing
    if spec.order == "front-to-back":
        order = np.arange(n)
    elif spec.order == "back-to-front":
        order = np.arange(n)[::-1]
    else:
        order = np.random.default_rng(spec.seed).permutation(n)
    w, h = spec.size[0] / 2, spec.size[1] / 2
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
    verts = np.empty((n, 4, 3))
    verts[:, :, :2] = corners
    verts[:, :, 2] = -depth[order][:, None]
    base = (np.arange(n) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    colors = np.asarray(spec.colors or [spec.color], dtype=np.float64)
    alphas = np.asarray(spec.alphas or [spec.alpha], dtype=np.float64)
    layer = order  # colours and alphas belong to the layer, whatever the submission order
    rgba = np.concatenate([colors[layer % len(colors)], alphas[layer % len(alphas)][:, None]], axis=1)
    return MeshData(verts.reshape(-1, 3), faces.astype(np.int64),
                    np.tile([0.0, 0.0, 1.0], (n * 4, 1)), np.repeat(rgba, 4, axis=0))


def sliver_fan(spec: m.SliverFan) -> MeshData:
    angles = np.radians(np.linspace(0.0, spec.arc_deg, spec.count + 1))
    rim = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1) * spec.radius
    verts = np.concatenate([[[0.0, 0.0, 0.0]], rim])
    faces = np.stack([np.zeros(spec.count, np.int64), np.arange(1, spec.count + 1),
                      np.arange(2, spec.count + 2)], axis=1)
    return MeshData(verts, faces, np.tile([0.0, 0.0, 1.0], (len(verts), 1)))


def leaves(spec: m.Leaves) -> MeshData:
    rng = np.random.default_rng(spec.seed)
    n = spec.count
    centre = (rng.random((n, 3)) - 0.5) * spec.spread
    axis_u = _unit(rng.normal(size=(n, 3)))
    axis_v = _unit(np.cross(axis_u, rng.normal(size=(n, 3))))
    u = axis_u * spec.size[0] / 2
    v = axis_v * spec.size[1] / 2
    verts = np.stack([centre - u - v, centre + u - v, centre + u + v, centre - u + v], axis=1)
    base = (np.arange(n) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    normal = np.repeat(_unit(np.cross(axis_u, axis_v)), 4, axis=0)
    colour = np.clip(np.asarray(spec.color) + (rng.random((n, 3)) - 0.5) * 2 * spec.color_jitter, 0.0, 1.0)
    rgba = np.repeat(np.concatenate([colour, np.full((n, 1), spec.alpha)], axis=1), 4, axis=0)
    return MeshData(verts.reshape(-1, 3), faces.astype(np.int64), normal, rgba)


def mesh_file(spec: m.Mesh, base_dir: Path, where: str) -> MeshData:
    import trimesh  # deferred: only scenes with mesh files pay for the import

    path = Path(spec.path)
    if not path.is_absolute():
        path = base_dir / path
    if not path.is_file():
        hint = spec.install_hint or "check the objects' path"
        raise ConfigError(f"{where}: mesh file {path} not found; {hint}")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except ImportError:       # trimesh looks for a text decoder when a file is neither text nor a binary mesh
        raise ConfigError(f"{where}: cannot read mesh {path}: not a readable {path.suffix.lstrip('.').upper()} file "
                          "(neither text nor binary data of that format)") from None
    except Exception as exc:  # trimesh raises many types for bad files
        raise ConfigError(f"{where}: cannot read mesh {path} ({type(exc).__name__}: {exc})") from None
    verts = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(loaded.faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ConfigError(f"{where}: mesh {path} has no triangles")
    if verts.ndim != 2 or verts.shape[1] != 3 or not np.isfinite(verts).all():
        raise ConfigError(f"{where}: mesh {path} has a vertex coordinate that is not a finite number")
    if faces.min() < 0 or faces.max() >= len(verts):
        bad = int(faces[(faces < 0) | (faces >= len(verts))][0])
        raise ConfigError(f"{where}: mesh {path} has a face naming vertex {bad}, outside its {len(verts):,} "
                          f"vertices (0..{len(verts) - 1})")
    if spec.normalize:
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        centre = lo / 2 + hi / 2
        with np.errstate(over="ignore", invalid="ignore"):
            radius = np.linalg.norm(verts - centre, axis=1).max()
        if not np.isfinite(radius):
            raise ConfigError(f"{where}: mesh {path} spans more than a float can hold; scale its coordinates down")
        verts = (verts - centre) / (radius if radius > 0 else 1.0)
    # area-weighted vertex normals
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(verts)
    for k in range(3):
        np.add.at(normals, faces[:, k], fn)
    return MeshData(verts, faces, _unit(normals))


GENERATORS = {"sphere": sphere, "box": box, "quad-grid": quad_grid,
              "layered-quads": layered_quads, "sliver-fan": sliver_fan, "leaves": leaves,
              "tet-ventricle": tet_ventricle}
