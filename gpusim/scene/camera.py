"""Camera and model matrices (OpenGL conventions, column vectors, right-handed)."""

from __future__ import annotations

import numpy as np


def look_at(eye, target, up) -> np.ndarray:
    """World-to-eye matrix: the camera at ``eye`` looks at ``target`` along -z."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    norm = np.linalg.norm(s)
    if norm < 1e-12:
        raise ValueError("camera up direction is parallel to the viewing direction")
    s /= norm
    u = np.cross(s, f)
    view = np.identity(4)
    view[0, :3], view[1, :3], view[2, :3] = s, u, -f
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """The glFrustum-style projection: eye z in [-near, -far] maps to NDC z in [-1, 1]."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0] = f / aspect
    proj[1, 1] = f
    proj[2, 2] = (far + near) / (near - far)
    proj[2, 3] = 2.0 * far * near / (near - far)
    proj[3, 2] = -1.0
    return proj


def model_matrix(translate, rotate_deg, scale) -> np.ndarray:
    """T * Rz * Ry * Rx * S: scale, rotate about x then y then z, then translate."""
    rx, ry, rz = np.radians(rotate_deg)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    out = np.identity(4)
    out[:3, :3] = rot_z @ rot_y @ rot_x @ np.diag(scale)
    out[:3, 3] = translate
    return out
