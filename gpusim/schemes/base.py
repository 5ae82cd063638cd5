"""The scheme interface: a registry of named, typed, parameterised scheme models.

A scheme is a frozen dataclass whose fields are its parameters (declared with
:func:`gpusim.config.param`: default, unit, description, bounds), registered
under its CLI name with :func:`register`. :meth:`Scheme.run` replays a trace
and returns a :class:`~gpusim.schemes.result.SchemeResult`. Schemes say *what*
happens (values, structures, operations); never *when* (that is gpusim.hw).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from gpusim.config import build, describe, to_dict
from gpusim.errors import ConfigError
from gpusim.metrics.composite import composite_runs
from gpusim.schemes.common.shading import shade_fragments
from gpusim.schemes.common.storage import effective_alpha, store_colour
from gpusim.schemes.result import SchemeResult
from gpusim.shaders import trace_fragment_shader
from gpusim.trace import FragmentTrace

#: name -> scheme class; filled by @register at import of gpusim.schemes.
REGISTRY: dict[str, type["Scheme"]] = {}


def register(name: str):
    """Class decorator: register a scheme class under its CLI ``name``."""
    def wrap(cls):
        if name in REGISTRY:
            raise ValueError(f"scheme {name!r} registered twice")
        cls.name = name
        REGISTRY[name] = cls
        return cls
    return wrap


@dataclasses.dataclass(frozen=True)
class Scheme:
    """Base of every scheme model; subclasses add parameter fields and implement ``simulate``."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    def params(self) -> dict:
        return to_dict(self)

    def run(self, trace: FragmentTrace) -> SchemeResult:
        """Replay ``trace`` through this scheme (functional model); its plan's shading passes run the scene's
        fragment shader first (gpusim.schemes.common.shading)."""
        result = self.simulate(trace)
        shade_fragments(result.plan, trace_fragment_shader(trace.meta))
        result.image = result.image.astype(np.float64, copy=False)
        return result

    def simulate(self, trace: FragmentTrace) -> SchemeResult:  # pragma: no cover - abstract
        raise NotImplementedError


def scheme_names() -> list[str]:
    return sorted(REGISTRY)


def scheme_class(name: str) -> type[Scheme]:
    if name not in REGISTRY:
        raise ConfigError(f"--scheme {name}: unknown scheme (valid: {', '.join(scheme_names())})")
    return REGISTRY[name]


def make_scheme(name: str, params: dict[str, Any] | None = None, where: str = "--param") -> Scheme:
    """Build scheme ``name`` from a parameter table; bad keys/values fail naming the key."""
    return build(scheme_class(name), dict(params or {}), where)


def describe_scheme(name: str) -> list[dict]:
    return describe(scheme_class(name))


def composite_image(trace: FragmentTrace, pix: np.ndarray, rgba: np.ndarray, alpha: np.ndarray,
                    dtype=np.float32) -> np.ndarray:
    """(H, W, 3) image from grouped runs in compositing order (float32 arithmetic by default)."""
    image = composite_runs(pix, rgba[:, :3], alpha, trace.pixel_count, trace.background, dtype)
    return image.reshape(trace.height, trace.width, 3)


def composite_stored(trace: FragmentTrace, pix: np.ndarray, order: np.ndarray, colour_format: str,
                     order_pix: np.ndarray | None = None) -> np.ndarray:
    """Image of fragments ``order`` (grouped by pixel, in compositing order) as a scheme stored them.

    Colours are rounded to ``colour_format``; opaque fragments count as alpha 1.
    ``pix`` is the pixel id of every fragment of ``trace``; ``order_pix`` is ``pix[order]`` when
    the caller has it.
    """
    rgba = store_colour(np.take(trace.rgba, order, axis=0), colour_format)   # take: rows faster than [order]
    order_pix = pix[order] if order_pix is None else order_pix
    return composite_image(trace, order_pix, rgba, effective_alpha(rgba, trace.opaque[order]))
