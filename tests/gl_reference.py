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


class CountPass:
    """The counting draw of ``clip`` triangles on a ``width`` x ``height`` float32 target,
    set up once so that it can be drawn again (the rasterizer benchmark times ``draw``)."""

    def __init__(self, ctx, clip: np.ndarray, width: int, height: int):
        import moderngl

        self.ctx, self.width, self.height = ctx, width, height
        self.prog = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
        self.tex = ctx.texture((width, height), 1, dtype="f4")
        self.fbo = ctx.framebuffer(color_attachments=[self.tex])
        self.fbo.use()
        ctx.viewport = (0, 0, width, height)
        ctx.disable(moderngl.CULL_FACE | moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        self.vbo = ctx.buffer(np.ascontiguousarray(clip, dtype="f4").reshape(-1, 4).tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "4f", "in_clip")])

    def clear(self) -> None:
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)

    def draw(self) -> None:
        """Draw every triangle once and wait until the GL has finished."""
        import moderngl

        self.vao.render(moderngl.TRIANGLES)
        self.ctx.finish()

    def counts(self) -> np.ndarray:
        data = np.frombuffer(self.fbo.read(components=1, dtype="f4"), dtype=np.float32)
        return data.reshape(self.height, self.width)

    def release(self) -> None:
        for obj in (self.vao, self.vbo, self.fbo, self.tex, self.prog):
            obj.release()


def gl_fragment_counts(ctx, clip: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) float fragment counts, row 0 = bottom (OpenGL window y)."""
    gl = CountPass(ctx, clip, width, height)
    gl.clear()
    gl.draw()
    counts = gl.counts()
    gl.release()
    return counts
