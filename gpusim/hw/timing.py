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
    if machine.partitions is None or not (machine.partitions.sample >= 0).any():
        return None
    read, write = rmw_windows(program, machine.partitions.sample, len(work.frag_pixel))
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


def run_full(work: Workload, gpu, result=None, reference=None, keep=None) -> tuple[dict, object]:
    """The event model on ``work`` (rows ``keep`` only, if given); (record, image with RMW artifacts or None)."""
    start = time.perf_counter()
    program = lower(work, gpu, keep)
    machine = Machine(gpu, program, work.width)
    total = machine.run()
    rec = _base(gpu, "full", program, len(program.op))
    rec["passes"] = [{"name": p.name, "kind": p.kind, "cycles": c, "warps": p.warps}
                     for p, c in zip(program.passes, machine.pass_cycles)]
    rec["units_built"] = machine.built_units()
    rec["units"] = machine.unit_summaries(total)
    rec["unit_stats"] = machine.unit_stats(total)
    image = _hazards(rec, program, machine, work, result if keep is None else None, reference)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), image


def tile_sample(work: Workload, gpu) -> tuple[np.ndarray, dict]:
    """Rows of the stream kept by the tile sample, and what was sampled."""
    s, c = work.stream, gpu.sample
    fragment_pass = np.array([p.threads == "fragment" for p in s.passes], bool)
    pixel_pass = np.array([p.threads == "pixel" for p in s.passes], bool)
    pi = s.pass_index.astype(np.int64)
    pixel = np.full(len(s), -1, np.int64)
    fr = fragment_pass[pi]
    if len(work.frag_pixel):
        pixel[fr] = work.frag_pixel[np.minimum(s.thread[fr], len(work.frag_pixel) - 1)]
    px = pixel_pass[pi]
    pixel[px] = s.thread[px]
    tiles_x = -(-work.width // c.tile)
    tile = np.where(pixel >= 0, (pixel // work.width // c.tile) * tiles_x + (pixel % work.width) // c.tile, -1)
    present = np.unique(tile[tile >= 0])
    rng = np.random.default_rng(c.seed)
    k = max(1, int(round(c.fraction * len(present)))) if len(present) else 0
    chosen = np.sort(rng.choice(present, size=k, replace=False)) if k else present
    keep = np.isin(tile, chosen)
    block = s.thread[tile < 0].astype(np.int64) // gpu.core.warp_size
    hashed = ((block * 2654435761 + c.seed * 97) & 0xFFFFFFFF) < int(c.fraction * 2**32)
    keep[tile < 0] = hashed
    total = np.bincount(pi, minlength=len(s.passes))
    kept = np.bincount(pi[keep], minlength=len(s.passes))
    empty = (kept == 0) & (total > 0)            # nothing of this pass in the sample: run it whole
    keep |= empty[pi]
    kept = np.bincount(pi[keep], minlength=len(s.passes))
    scale = np.where(kept > 0, total / np.maximum(kept, 1), 1.0)
    return keep, {"tiles": int(len(present)), "tiles_sampled": int(k), "tile": c.tile, "seed": c.seed,
                  "fraction": c.fraction, "operations_sampled": int(keep.sum()), "scale": scale.tolist()}


def run_sampled(work: Workload, gpu, result=None, reference=None) -> tuple[dict, None]:
    start = time.perf_counter()
    keep, info = tile_sample(work, gpu)
    # the sample gets its share of the rasterizer, so a raster-bound pass scales back to the whole
    share = max(1, int(keep.sum())) / max(1, len(work.stream))
    sample_gpu = replace(gpu, raster=replace(gpu.raster, triangles_per_cycle=gpu.raster.triangles_per_cycle / share))
    rec, _ = run_full(work, sample_gpu, keep=keep)
    for p, f in zip(rec["passes"], info.pop("scale")):     # both in pass order
        p["sampled_cycles"] = p["cycles"]
        p["cycles"] = int(round(p["cycles"] * f))
    total = sum(p["cycles"] for p in rec["passes"])
    rec["fidelity"] = "sampled"
    rec["sample"] = info
    rec["operations"] = int(len(work.stream))
    ops_scale = len(work.stream) / max(1, info["operations_sampled"])
    rec["rmw_hazards"] = int(round(rec.get("rmw_hazards", 0) * ops_scale))
    rec["rmw_hazard_pixels"] = int(round(rec.get("rmw_hazard_pixels", 0) * ops_scale))
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), None


def run_analytic(work, gpu, result=None, reference=None) -> tuple[dict, None]:
    """Bounds from the scheme's operation groups (no OpStream, no events); see gpusim.hw.analytic."""
    from gpusim.hw.analytic import analytic_timing
    start = time.perf_counter()
    rec = analytic_timing(result, work, gpu)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, rec.pop("total")), None


LEVELS = {"analytic": run_analytic, "sampled": run_sampled, "full": run_full}
