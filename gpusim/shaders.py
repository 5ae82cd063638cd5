"""The scene's fragment shader: the material program every shaded fragment runs, whatever the scheme.

A multi-fragment scheme wraps the scene's material shader: the hardware
pipeline runs it in the pixel shader of every geometry pass that needs the
fragment's colour (or only its alpha), FreePipe's software rasterizer in each
fragment's iteration of its triangle loop. Its instructions are the same for
every scheme, so they belong to the scene (``fragment_shader`` in a scene file,
recorded in the trace's ``scene_config``); the schemes add their own work on
top (gpusim.schemes.common.alu).

Counts are scalar instructions of one thread with the conventions of
gpusim.schemes.common.alu: one per scalar operation a compiler emits (an fma,
a compare, a select, a conversion, a transcendental; pow is log2, a multiply
and exp2; a vector operation per component, a dot product of 3 as 3); an
attribute interpolation is one instruction per component, a screen-space
derivative a quad swizzle and a subtract per component.

======================= ====== ===== ===================================================================
name                    colour alpha what it is
======================= ====== ===== ===================================================================
none                    0      0     the trace's colours are the shader's output: no material program is
                                     timed (every scene that does not say otherwise)
lucid-simple            106    4     LucidRaster's hardware renderer (seed 002 section 4: "the fragment
                                     shader is almost identical in both renderers"): nadult/lucid
                                     data/shaders/simple_material.glsl, fragment stage, on a look-alike
                                     (no vertex normals, colours or texture; an instance colour)
======================= ====== ===== ===================================================================

``lucid-simple``, colour (106): the normal flag's uniform test (2); the
world position's interpolation (3), its two derivatives (12), their cross
product (6) and normalisation (a dot of 3, rsqrt, 3 multiplies: 7); the
vertex colour's interpolation (4) times the material colour (4); the texture
flag's test (2); the light value, max(0, dot(-sun, n) x 0.7 + 0.3) (5); then
finalShading, counted as in LucidRaster's own shadeSample (alu.SHADE_SAMPLE):
SRGBToLinear (24), the ambient and sun light (9), their product with the
colour (6), linearToSRGB (21); the alpha's move (1). The ROP converts the
output to the framebuffer's format, so no encode is counted. Alpha alone
(a pass that only needs the fragment's opacity, as MBOIT's moment pass): the
vertex alpha's interpolation, its product with the material alpha, the
texture flag's test (4).

LucidRaster's own sample shading (its shadeSample, alu.SHADE_SAMPLE) always
lights its samples, as its source does; on a ``lucid-simple`` scene the
hardware-pipeline schemes light theirs the same way, which is the comparison
seed 002 makes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Mapping

#: what a geometry pass needs of the fragment shader: the fragment's colour, its alpha only, or nothing (a
#: depth-only pass)
Shading = Literal["colour", "alpha", "none"]
SHADINGS = ("colour", "alpha", "none")


@dataclass(frozen=True)
class FragmentShader:
    """A material fragment program: its scalar instructions per fragment lane."""

    name: str
    colour: int        # instructions: the whole program (the fragment's colour and alpha)
    alpha: int         # instructions: the alpha alone
    source: str

    def instructions(self, shading: str) -> int:
        """Instructions a lane runs in a pass that needs ``shading`` of the fragment."""
        if shading not in SHADINGS:
            raise ValueError(f"unknown shading {shading!r} (valid: {', '.join(SHADINGS)})")
        return {"colour": self.colour, "alpha": self.alpha, "none": 0}[shading]


FRAGMENT_SHADERS: dict[str, FragmentShader] = {
    "none": FragmentShader("none", 0, 0, "the trace's colours are final; no material program is timed"),
    "lucid-simple": FragmentShader(
        "lucid-simple", 2 + 3 + 12 + 6 + 7 + 4 + 4 + 2 + 5 + 24 + 9 + 6 + 21 + 1, 1 + 1 + 2,
        "nadult/lucid data/shaders/simple_material.glsl (fragment stage), flat normal, instance colour"),
}
ShaderName = Literal["none", "lucid-simple"]


def fragment_shader(name: str) -> FragmentShader:
    """The registered fragment shader ``name``; an unknown name lists the valid ones."""
    try:
        return FRAGMENT_SHADERS[name]
    except KeyError:
        raise ValueError(f"unknown fragment shader {name!r} (valid: {', '.join(FRAGMENT_SHADERS)})") from None


def trace_fragment_shader(meta: Mapping) -> FragmentShader:
    """The fragment shader a trace's scene declares (``meta['scene_config']['fragment_shader']``); ``none`` for
    a trace that records none (an imported CSV, a histogram scene, a trace made before the key existed)."""
    config = meta.get("scene_config") or {}
    name = config.get("fragment_shader", "none") if isinstance(config, Mapping) else "none"
    try:
        return fragment_shader(name)
    except ValueError as e:
        raise ValueError(f"the trace's scene_config.fragment_shader: {e}; make the trace again from its scene "
                         f"with a known shader") from None
