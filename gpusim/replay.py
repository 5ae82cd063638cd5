"""Replay a trace through a scheme and gather the run's record.

Two steps, shared by ``gpusim replay`` and the experiment runner:
:func:`run_functional` (the scheme's functional model, its image error against
the exact reference) and :func:`run_timing` (one timing level on that result).
An experiment runs the first once per scene, scheme and parameter set and the
second once per GPU and fidelity level.
"""

from __future__ import annotations

import math
import time
from typing import Any

from gpusim.config import parse_override
from gpusim.errors import ConfigError, GpusimError
from gpusim.hw import FIDELITIES
from gpusim.hw.gpu import load_gpu
from gpusim.metrics import composite_exact, image_error
from gpusim.schemes import make_scheme
from gpusim.schemes.result import SchemeResult, Stat
from gpusim.trace import FragmentTrace

ERROR_KEYS = ("rmse", "psnr", "differing_pixels", "differing_share", "max_abs")


def jsonable(value):
    """A record ready for JSON: non-finite floats as "inf"/"-inf" (NaN as null), tuples as lists."""
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    return value


def parse_params(items: list[str] | None) -> dict[str, Any]:
    """``["layers=8", "packing=true"]`` -> {"layers": 8, "packing": True} (values read as TOML)."""
    params: dict[str, Any] = {}
    for text in items or []:
        parts, value = parse_override(text, "--param", f"{text.strip() or 'layers'}=8", "NAME=VALUE")
        if len(parts) != 1:
            raise ConfigError(f"--param {text}: scheme parameters have no dots (e.g. --param layers=8)")
        params[parts[0]] = value
    return params


def run_functional(trace: FragmentTrace, scheme: str, params: dict[str, Any] | None = None,
                   reference=None, where: str | None = None) -> tuple[SchemeResult, dict, Any]:
    """The scheme's functional model on ``trace``: (result, record, reference image).

    ``reference`` (the exact composite of ``trace``) is computed when not given.
    """
    model = make_scheme(scheme, params, where=where or f"--scheme {scheme} --param")
    start = time.perf_counter()
    try:
        result = model.run(trace)
    except ValueError as exc:          # a value the model cannot take (e.g. NaN depth in memory)
        raise GpusimError(f"{scheme}: {exc}") from None
    wall = time.perf_counter() - start
    if reference is None:
        reference = composite_exact(trace)
    error = image_error(result.image, reference)
    record = {
        "scheme": scheme,
        "params": result.params,
        "trace": trace.source,
        "scene": trace.meta.get("scene"),
        "width": trace.width,
        "height": trace.height,
        "fragments": result.fragments,
        "pixels": result.pixels,
        "geometry_passes": result.geometry_passes,
        "passes": [{"name": p.name, "kind": p.kind} for p in result.passes],
        "footprint_bytes": result.footprint,
        "footprint_used_bytes": result.footprint_used,
        "accesses": result.accesses,
        "dropped_fragments": result.dropped_fragments,
        "overflowed_pixels": result.overflowed_pixels,
        "stats": {k: {"value": v.value, "unit": v.unit, "doc": v.doc} for k, v in result.stats.items()
                  if isinstance(v, Stat)},
        "error": {k: error[k] for k in ERROR_KEYS},
        "wall_seconds": wall,
    }
    return result, record, reference


def run_timing(result: SchemeResult, trace: FragmentTrace, fidelity: str, gpu=None, reference=None,
               progress=None) -> tuple[dict, dict | None, Any]:
    """One timing level on a functional result: (timing record, resolved GPU config or None, timed image or
    None). The timed image is the image in event order, with its RMW artifacts, where the level replays
    them. ``progress``: a tqdm-like bar the full level counts its warps on."""
    if fidelity not in FIDELITIES:
        raise ConfigError(f"--fidelity {fidelity}: unknown fidelity level (valid: {', '.join(FIDELITIES)})")
    if gpu is None and fidelity != "thesis":
        gpu = load_gpu()
    start = time.perf_counter()
    timing, timed_image = FIDELITIES[fidelity](result, trace, gpu, reference, progress=progress)
    timing = timing | {"wall_seconds": time.perf_counter() - start}
    return timing, (gpu.to_dict() if gpu is not None else None), timed_image


def replay(trace: FragmentTrace, scheme: str, params: dict[str, Any] | None = None,
           fidelity: str | None = None, gpu=None, progress=None) -> tuple[SchemeResult, dict, Any, Any]:
    """Run ``scheme`` (and the timing model ``fidelity`` on ``gpu``, if given).

    Returns (result, record, image, reference). With a timing level that
    replays RMW hazards, ``result.extras["timed_image"]`` holds the image in
    event order (with its artifacts).
    """
    if fidelity is not None and fidelity not in FIDELITIES:
        raise ConfigError(f"--fidelity {fidelity}: unknown fidelity level (valid: {', '.join(FIDELITIES)})")
    result, record, reference = run_functional(trace, scheme, params)
    if fidelity is not None:
        timing, gpu_config, timed_image = run_timing(result, trace, fidelity, gpu, reference, progress)
        record["timing"] = timing
        if gpu_config is not None:
            record["gpu_config"] = gpu_config
        if timed_image is not None:
            result.extras["timed_image"] = timed_image
    return result, record, result.image, reference
