"""The fidelity levels of the timing model: ``analytic``, ``sampled`` and ``full``.

* ``full``: the event model (gpusim.hw.machine) on every operation.
* ``sampled``: the event model on the operations of a random sample of
  non-empty screen tiles (``sample.tile``, ``sample.fraction``, ``sample.seed``)
  and of the same share of threads without a pixel (clear passes), on a
  machine whose rasterizer is sped up by the same share; each pass's cycles
  are scaled by its operations in all / in the sample.
* ``analytic``: per pass, the largest of the units' work / throughput bounds
  (issue ports, DRAM channels, atomic units and their hottest address, ROPs)
  and the warps' latency-chain bound, plus one round trip; no events.

Each returns the record ``replay --json`` prints under ``timing``: cycles,
microseconds at the GPU's clock, per-pass cycles, per-unit utilisation, RMW
hazards, and the units built (a unit no operation reaches is not built).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from gpusim.hw.hazards import count_hazards, rmw_windows
from gpusim.hw.lower import Program, Workload, lower
from gpusim.hw.machine import Machine


def _base(gpu, fidelity: str, program: Program, n_ops: int) -> dict:
    return {"fidelity": fidelity, "gpu": gpu.name, "instructions": int(program.instructions),
            "operations": int(n_ops)}


def _finish(rec: dict, gpu, cycles: int) -> dict:
    rec["cycles"] = int(cycles)
    rec["microseconds"] = cycles / gpu.core.clock_mhz
    return rec


def _hazards(rec: dict, program: Program, machine: Machine, work: Workload, result, reference, scale=1.0):
    """RMW hazards from the event times, and the image replayed in event order."""
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = 0, 0
    sample = machine.partitions.sample() if machine.partitions is not None else None
    if sample is None or not (sample >= 0).any():
        return None
    read, write = rmw_windows(program, sample, len(work.frag_pixel))
    h, hp = count_hazards(work.frag_pixel, read, write)
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = int(round(h * scale)), int(round(hp * scale))
    replay = result.extras.get("rmw_replay") if result is not None else None
    if replay is None or scale != 1.0:
        return None
    image, stats = replay(read, write)
    if reference is not None:
        from gpusim.metrics import image_error
        err = image_error(image, reference)
        rec["rmw_image_error"] = {k: err[k] for k in ("rmse", "psnr", "differing_pixels", "differing_share",
                                                      "max_abs")}
    rec["rmw_replay"] = stats
    return image


def run_full(work: Workload, gpu, result=None, reference=None, program: Program | None = None
             ) -> tuple[dict, object]:
    """The event model on ``work`` (or on an already lowered sample of it); (record, image with RMW artifacts
    or None)."""
    start = time.perf_counter()
    sampled = program is not None
    if program is None:
        program = lower(work, gpu)
    machine = Machine(gpu, program, work.width)
    total = machine.run()
    rec = _base(gpu, "full", program, program.operations)
    rec["passes"] = [{"name": p.name, "kind": p.kind, "cycles": c, "warps": p.warps}
                     for p, c in zip(program.passes, machine.pass_cycles)]
    rec["units_built"] = machine.built_units()
    rec["units"] = machine.unit_summaries(total)
    rec["unit_stats"] = machine.unit_stats(total)
    image = _hazards(rec, program, machine, work, None if sampled else result, reference)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), image


def tile_sample(work: Workload, gpu):
    """The threads the tile sample keeps: ``keep(pass_index, threads) -> mask``, and what was sampled.

    Fragment threads are kept by the screen tile of their pixel, pixel threads
    by their own tile, and other threads (memory entries) by a hash of their
    warp-sized block, each at ``sample.fraction``.
    """
    c, plan = gpu.sample, work.plan
    tiles_x = -(-work.width // c.tile)

    def tile_of(pixel):
        return (pixel // work.width // c.tile) * tiles_x + (pixel % work.width) // c.tile

    present = np.zeros(tiles_x * -(-work.height // c.tile), bool)
    if any(p.threads == "fragment" for p in plan.passes) and len(work.frag_pixel):
        present[tile_of(work.frag_pixel)] = True
    if any(p.threads == "pixel" for p in plan.passes):
        present[:] = True
    tiles = np.flatnonzero(present)
    rng = np.random.default_rng(c.seed)
    k = max(1, int(round(c.fraction * len(tiles)))) if len(tiles) else 0
    chosen = np.zeros(len(present), bool)
    chosen[rng.choice(tiles, size=k, replace=False) if k else tiles] = True
    threshold = int(c.fraction * 2**32)

    def keep(p: int, threads: np.ndarray) -> np.ndarray:
        kind = plan.passes[p].threads
        if kind == "fragment":
            return chosen[tile_of(work.frag_pixel[threads])]
        if kind == "pixel":
            return chosen[tile_of(threads)]
        block = threads // gpu.core.warp_size
        return ((block * 2654435761 + c.seed * 97) & 0xFFFFFFFF) < threshold

    return keep, {"tiles": int(len(tiles)), "tiles_sampled": int(k), "tile": c.tile, "seed": c.seed,
                  "fraction": c.fraction}


def run_sampled(work: Workload, gpu, result=None, reference=None) -> tuple[dict, None]:
    start = time.perf_counter()
    keep, info = tile_sample(work, gpu)
    program = lower(work, gpu, keep)
    kept, total = sum(p.operations for p in program.passes), sum(p.operations_total for p in program.passes)
    # the sample gets its share of the rasterizer, so a raster-bound pass scales back to the whole
    share = max(1, kept) / max(1, total)
    sample_gpu = replace(gpu, raster=replace(gpu.raster, triangles_per_cycle=gpu.raster.triangles_per_cycle / share))
    rec, _ = run_full(work, sample_gpu, program=program)
    for p, pp in zip(rec["passes"], program.passes):     # both in pass order
        p["sampled_cycles"] = p["cycles"]
        p["cycles"] = int(round(p["cycles"] * (pp.operations_total / pp.operations if pp.operations else 1.0)))
    rec["fidelity"] = "sampled"
    rec["sample"] = info | {"operations_sampled": int(kept)}
    rec["operations"] = int(total)
    ops_scale = total / max(1, kept)
    rec["rmw_hazards"] = int(round(rec.get("rmw_hazards", 0) * ops_scale))
    rec["rmw_hazard_pixels"] = int(round(rec.get("rmw_hazard_pixels", 0) * ops_scale))
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, sum(p["cycles"] for p in rec["passes"])), None


def run_analytic(work, gpu, result=None, reference=None) -> tuple[dict, None]:
    """Bounds from the scheme's operation groups (no OpStream, no events); see gpusim.hw.analytic."""
    from gpusim.hw.analytic import analytic_timing
    start = time.perf_counter()
    rec = analytic_timing(result, work, gpu)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, rec.pop("total")), None


LEVELS = {"analytic": run_analytic, "sampled": run_sampled, "full": run_full}
