"""The standing stability matrix: every scheme x every timing level x every built-in scene, small.

Each run finishes with finite images and whole-cycle results, or refuses in one line that names the limit
and advice that works (the analytic level, which has no operation limit, must then finish). The stiff
scene (stress-layers: 4,097 layers on a few pixels beside single-layer pixels) is included at the same
size. No valid configuration may deadlock.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from gpusim.errors import GpusimError
from gpusim.hw import load_gpu
from gpusim.hw.machine import NoProgress
from gpusim.replay import run_functional, run_timing
from gpusim.scene import load_scene, trace_scene
from gpusim.scene.load import builtin_scenes as scene_files
from gpusim.scene.model import Mesh
from gpusim.schemes import scheme_names

SIZE = 32
LEVELS = ("analytic", "sampled", "full")
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def builtin_scenes() -> list[str]:
    """The stand-alone built-in scenes (not the papers' look-alikes)."""
    return [s for s in scene_files() if not s.startswith(("like-", "thesis-"))]


def _skip_without_meshes(scene, base: Path) -> None:
    """Skip (fail in CI, which installs them) when a mesh file the scene needs is not on this machine:
    the bunny comes from Debian's glmark2-data."""
    for obj in getattr(scene, "objects", ()):
        if isinstance(obj, Mesh):
            path = Path(obj.path) if Path(obj.path).is_absolute() else base / obj.path
            if not path.is_file():
                reason = f"mesh file {path} missing ({obj.install_hint or 'check the path'})"
                if IN_CI:
                    pytest.fail(f"{reason}; CI must install it: scripts/test.sh")
                pytest.skip(reason)


@pytest.mark.parametrize("scene", builtin_scenes())
def test_every_scheme_and_level_finishes_or_refuses_in_one_line(scene):
    loaded = load_scene(scene, [f"screen.width={SIZE}", f"screen.height={SIZE}"])
    _skip_without_meshes(*loaded)
    trace = trace_scene(*loaded)
    # the sampled level's own design (a replicate on 1 of the 30 SMs), as configs/experiments/stability.toml
    # runs it: its default minimum of 30 tiles would simulate every one of these 32x32 runs whole, the full
    # level's run a second time
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    refused = []
    for scheme in scheme_names():
        result, record, reference = run_functional(trace, scheme, {})
        assert np.isfinite(result.image).all(), f"{scheme}: non-finite image"
        assert record["dropped_fragments"] >= 0 and isinstance(record["dropped_fragments"], int)
        for level in LEVELS:
            try:
                timing, _, _ = run_timing(result, trace, level, gpu, reference)
            except NoProgress as exc:               # a valid configuration must never deadlock
                pytest.fail(f"{scene} {scheme} {level}: {exc}")
            except GpusimError as exc:
                message = str(exc)
                assert "\n" not in message and level != "analytic", f"{scheme} {level}: {message}"
                assert "runner.max_operations" in message and "--fidelity analytic" in message, message
                refused.append((scheme, level))
                continue
            assert isinstance(timing["cycles"], int) and timing["cycles"] > 0, (scheme, level)
            assert all(isinstance(p["cycles"], int) and p["cycles"] >= 0 for p in timing["passes"])
    if scene != "stress-layers":
        assert not refused, refused
