"""Per-pixel fragment counts from a real OpenGL implementation (Mesa llvmpipe via EGL).

Used by the rasterizer agreement test: the same clip-space triangles are drawn
with additive blending of 1.0 per fragment into a float32 target, culling and
depth testing off, so each pixel's value is its fragment count.
"""

from __future__ import annotations

import os

import numpy as np

VERTEX = """
#version 330
in vec4 in_clip;
void main() { gl_Position = in_clip; }
"""
FRAGMENT = """
#version 330
out vec4 count;
void main() { count = vec4(1.0, 0.0, 0.0, 1.0); }
"""


def make_context():
    """A standalone EGL context on Mesa's software rasterizer; raises if unavailable."""
    os.environ.setdefault("LIBGL_ALWAYS_SOFTWARE", "1")
    os.environ.setdefault("GALLIUM_DRIVER", "llvmpipe")
    import moderngl

    return moderngl.create_standalone_context(backend="egl")


def gl_fragment_counts(ctx, clip: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) float fragment counts, row 0 = bottom (OpenGL window y)."""
    import moderngl

    prog = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
    tex = ctx.texture((width, height), 1, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[tex])
    fbo.use()
    ctx.viewport = (0, 0, width, height)
    ctx.disable(moderngl.CULL_FACE | moderngl.DEPTH_TEST)
    ctx.enable(moderngl.BLEND)
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    ctx.blend_equation = moderngl.FUNC_ADD
    fbo.clear(0.0, 0.0, 0.0, 0.0)
    vbo = ctx.buffer(np.ascontiguousarray(clip, dtype="f4").reshape(-1, 4).tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "4f", "in_clip")])
    vao.render(moderngl.TRIANGLES)
    data = np.frombuffer(fbo.read(components=1, dtype="f4"), dtype=np.float32)
    for obj in (vao, vbo, fbo, tex, prog):
        obj.release()
    return data.reshape(height, width)
