"""The golden timing table: every scheme on two scenes, three GPUs and three fidelity levels.

Kept in ``tests/fixtures/timing_golden.json``; ``test_timing_golden`` checks that the
model gives the same cycles, per-pass cycles, per-unit busy cycles and requests, and
RMW hazards. Regenerate only for a
deliberate change of the model, and explain each difference in the commit:

    .venv/bin/python tests/timing_golden.py --write
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

FIXTURE = Path(__file__).with_name("fixtures") / "timing_golden.json"
SCENES = ("nested-spheres", "default")
SIZE = 96
GPUS = ("gtx280", "geforce7900gtx", "modern")
LEVELS = ("analytic", "sampled", "full")
#: every registered scheme at its defaults, and the variants that reach the other units
VARIANTS = {"kbuffer:scoreboard": ("kbuffer", {"hw": "scoreboard"}),
            "kbuffer:blender": ("kbuffer", {"hw": "blender"}),
            "kbuffer:heuristic": ("kbuffer", {"order": "centroid", "batch": 32}),
            "freepipe-mdts:packing": ("freepipe-mdts", {"packing": True, "alpha": 0.5})}


def runs():
    from gpusim.schemes import scheme_names
    return {name: (name, {}) for name in scheme_names()} | VARIANTS


def _timing_row(rec: dict) -> dict:
    """The figures the golden table keeps from one timing record."""
    row = {"cycles": rec["cycles"], "passes": [p["cycles"] for p in rec["passes"]],
           "rmw_hazards": rec.get("rmw_hazards"), "rmw_hazard_pixels": rec.get("rmw_hazard_pixels"),
           "units_built": sorted(rec.get("units_built", []))}
    units = {}
    for name, u in sorted(rec.get("units", {}).items()):
        units[name] = {k: v for k, v in sorted(u.items()) if not k.startswith("utilisation")}
    row["units"] = units
    if rec["fidelity"] == "analytic":
        row["bounds"] = [p.get("bound") for p in rec["passes"]]
    return row


def collect(scenes=SCENES, gpus=GPUS, levels=LEVELS, only=None) -> dict:
    """``{"scene/run/gpu/level": row}``; a run that fails records its error message."""
    from gpusim.errors import GpusimError
    from gpusim.hw import load_gpu
    from gpusim.replay import run_functional, run_timing
    from gpusim.scene import load_scene, trace_scene
    table = {}
    for scene in scenes:
        trace = trace_scene(*load_scene(scene, [f"screen.width={SIZE}", f"screen.height={SIZE}"]))
        for label, (scheme, params) in runs().items():
            if only is not None and label not in only:
                continue
            result, _, reference = run_functional(trace, scheme, params)
            for gpu_name in gpus:
                gpu = load_gpu(gpu_name, ["runner.workers=1"])
                for level in levels:
                    key = f"{scene}/{label}/{gpu_name}/{level}"
                    try:
                        rec, _, _ = run_timing(result, trace, level, gpu, reference)
                        table[key] = _timing_row(rec)
                    except GpusimError as exc:
                        table[key] = {"error": str(exc).split(":")[0]}
    return table


if __name__ == "__main__":
    import time
    start = time.perf_counter()
    table = collect()
    if "--write" in sys.argv:
        FIXTURE.parent.mkdir(exist_ok=True)
        FIXTURE.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
    print(f"{len(table)} rows in {time.perf_counter() - start:.1f} s")
