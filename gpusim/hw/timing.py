"""The fidelity levels of the timing model: ``analytic``, ``sampled``, ``full`` (and ``thesis``).

* ``full``: the event model (gpusim.hw.machine) on every operation.
* ``sampled``: the event model on the operations of a random sample of
  non-empty screen tiles (``sample.tile``, ``sample.fraction``, ``sample.seed``)
  and of the same share of threads without a pixel (clear passes) and of
  software-rasterizer triangles that cover no pixel, on a machine whose front
  end's per-triangle stages are sped up by the same share, and again on a
  random half of that sample; each pass's cycles are extrapolated along the
  line through the two (a fixed latency part plus a part that grows with the
  work) to all of its operations.
* ``analytic``: per pass, the largest of the units' work / throughput bounds
  (issue ports, DRAM channels, atomic units and their hottest address, ROPs)
  and the warps' latency-chain bound, plus one round trip; no events.

Each returns the record ``replay --json`` prints under ``timing``: cycles,
microseconds at the GPU's clock, per-pass cycles, per-unit utilisation, RMW
hazards, and the units built (a unit no operation reaches is not built).
"""

from __future__ import annotations

import time

import numpy as np

from gpusim.hw.hazards import count_hazards, machine_windows
from gpusim.hw.lower import Workload, hashed, lower
from gpusim.hw.machine import Machine
from gpusim.hw.program import Program
from gpusim.hw.stream import plan_chunks, run_streamed, unit_records
from gpusim.hw.thesis import thesis_timing
from gpusim.opplan import OPS


def _base(gpu, fidelity: str, instructions: int, n_ops: int) -> dict:
    return {"fidelity": fidelity, "gpu": gpu.name, "instructions": int(instructions), "operations": int(n_ops)}


def _finish(rec: dict, gpu, cycles: int) -> dict:
    rec["cycles"] = int(cycles)
    rec["microseconds"] = cycles / gpu.core.clock_mhz
    return rec


def _hazards(rec: dict, windows, work: Workload, result, reference):
    """RMW hazards from the event times (the RMW ``windows``, or None), and the image replayed in event
    order."""
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = 0, 0
    if windows is None:
        return None
    read, write = windows
    h, hp = count_hazards(work.frag_pixel, read, write)
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = int(h), int(hp)
    replay = result.extras.get("rmw_replay") if result is not None else None
    if replay is None:
        return None
    image, stats = replay(read, write)
    if reference is not None:
        from gpusim.metrics import image_error
        err = image_error(image, reference)
        rec["rmw_image_error"] = {k: err[k] for k in ("rmse", "psnr", "differing_pixels", "differing_share",
                                                      "max_abs")}
    rec["rmw_replay"] = stats
    return image


def run_full(work: Workload, gpu, result=None, reference=None, program: Program | None = None,
             progress=None) -> tuple[dict, object]:
    """The event model on ``work`` (or on an already lowered sample of it); (record, image with RMW artifacts
    or None). ``progress``: a tqdm-like bar to count the warps done on."""
    start = time.perf_counter()
    sampled = program is not None
    chunks = None if sampled else plan_chunks(work, gpu)
    if chunks is not None:               # too large to lower at once: a chunk of passes at a time
        return _run_streamed(work, gpu, chunks, result, reference, progress, start)
    if program is None:
        program = lower(work, gpu)
    machine = Machine(gpu, program, work.width, progress)
    total = machine.run()
    rec = _base(gpu, "full", program.instructions, program.operations)
    rec["passes"] = [{"name": p.name, "kind": p.kind, "cycles": c, "warps": p.warps}
                     for p, c in zip(program.passes, machine.pass_cycles)]
    rec["units_built"] = machine.built_units()
    rec["units"] = machine.unit_summaries(total)
    rec["unit_stats"] = machine.unit_stats(total)
    image = _hazards(rec, machine_windows(program, machine, len(work.frag_pixel)), work,
                     None if sampled else result, reference)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), image


def _run_streamed(work: Workload, gpu, chunks, result, reference, progress, start: float):
    """:func:`run_full` a chunk of passes at a time (gpusim.hw.stream); the same record, plus ``streamed``."""
    passes, units, instructions, operations, windows = run_streamed(work, gpu, chunks, progress)
    total = sum(p[2] for p in passes)
    rec = _base(gpu, "full", instructions, operations)
    rec["passes"] = [{"name": name, "kind": kind, "cycles": c, "warps": warps} for name, kind, c, warps in passes]
    rec["units_built"] = list(units)
    rec["units"], rec["unit_stats"] = unit_records(units, total)
    image = _hazards(rec, windows, work, result, reference)
    rec["streamed"] = {"chunks": len(chunks), "passes": [list(c) for c in chunks]}
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), image


def tile_sample(work: Workload, gpu, halve: bool = False):
    """The threads the tile sample keeps: ``keep(pass_index, threads) -> mask``, and what was sampled.

    Fragment threads are kept by the screen tile of their pixel, pixel threads
    by their own tile, and other threads (memory entries) by a hash of their
    warp-sized block, each at ``sample.fraction``. ``halve``: half of that
    sample (a random half of its tiles, or half the threads of a single tile;
    half of its hash range), nested in it.
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
    picked = rng.choice(tiles, size=k, replace=False) if k else tiles      # in random order
    split_tiles = halve and len(picked) > 1
    if split_tiles:
        picked = picked[:len(picked) // 2]
    chosen = np.zeros(len(present), bool)
    chosen[picked] = True
    threshold = int(c.fraction * 2**32) // (2 if halve else 1)

    def keep(p: int, threads: np.ndarray) -> np.ndarray:
        kind = plan.passes[p].threads
        if kind in ("fragment", "pixel"):
            mask = chosen[tile_of(work.frag_pixel[threads] if kind == "fragment" else threads)]
            if halve and not split_tiles:          # a single tile: half of its threads
                mask &= hashed(threads, 1 << 31, c.seed)
            return mask
        return hashed(threads // gpu.core.warp_size, threshold, c.seed)

    return keep, {"tiles": int(len(tiles)), "tiles_sampled": int(len(picked)), "tile": c.tile, "seed": c.seed,
                  "fraction": c.fraction}


def _sample_run(work: Workload, gpu, keep):
    """The event model on the threads ``keep`` keeps, on a machine whose front end gets their share of the
    triangles (so a front-end-bound pass scales with the sample too); (record, program)."""
    program = lower(work, gpu, keep)
    rec, _ = run_full(work, gpu, program=program)     # the front end gets the sample's share (Program)
    return rec, program


def extrapolate(t1: float, s1: float, t2: float, s2: float, one_round: bool) -> float:
    """A pass's cycles on all its operations from two nested samples: ``t1`` cycles on share ``s1`` of them,
    ``t2`` on ``s2 < s1``. A pass takes a fixed part (its slowest thread's latency chain, the pipeline) plus
    a part that grows with the work, so the line through the two samples is followed to share 1. A share
    of 1 is the whole pass (exact). When both samples hold the same operations (a small pass), there is no
    line: a pass of at most a warp per SM (``one_round``) keeps the sample's time (its slowest warp's), a
    larger one scales it with the work."""
    if s1 >= 1.0:
        return t1
    if s2 >= 1.0:
        return t2
    if s2 <= 0.0 or s1 - s2 < 1e-9:
        return t1 if one_round else t1 / s1
    slope = max(0.0, (t1 - t2) / (s1 - s2))
    return t1 + (1.0 - s1) * slope


def run_sampled(work: Workload, gpu, result=None, reference=None) -> tuple[dict, None]:
    start = time.perf_counter()
    keep, info = tile_sample(work, gpu)
    rec, program = _sample_run(work, gpu, keep)
    rec2, program2 = _sample_run(work, gpu, tile_sample(work, gpu, halve=True)[0])
    resident = gpu.core.sms * gpu.core.warp_size         # lanes of a warp per SM
    for p, pp, p2, pp2 in zip(rec["passes"], program.passes, rec2["passes"], program2.passes):   # pass order
        total = pp.operations_total
        s1 = pp.operations / total if pp.operations else 1.0        # a pass with none kept ran whole
        s2 = pp2.operations / total if pp2.operations else 1.0
        p["sampled_cycles"] = p["cycles"]
        p["cycles"] = int(round(extrapolate(p["cycles"], s1, p2["cycles"], s2, pp.lanes / s1 <= resident)))
    kept, total = sum(p.operations for p in program.passes), sum(p.operations_total for p in program.passes)
    rec["fidelity"] = "sampled"
    rec["sample"] = info | {"operations_sampled": int(kept),
                            "operations_half_sample": int(sum(p.operations for p in program2.passes))}
    rec["operations"] = int(total)
    # hazards scale with the fragments that read-modify-write: the sample's share of them (never more than
    # there are such fragments)
    (frags_all, pixels_all), (frags_kept, pixels_kept) = _rmw_threads(work.plan, work), _rmw_threads(program, work)
    for key, every, kept in (("rmw_hazards", frags_all, frags_kept), ("rmw_hazard_pixels", pixels_all, pixels_kept)):
        rec[key] = min(every, int(round(rec.get(key, 0) * every / kept))) if kept else 0
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, sum(p["cycles"] for p in rec["passes"])), None


def _rmw_threads(source, work: Workload) -> tuple[int, int]:
    """Fragment threads with an ``rmw_read``, and their pixels: of an OpPlan, or of a lowered (sampled)
    Program."""
    if isinstance(source, Program):
        rows = source.rows_of("coalescer")
        threads = rows.thread[rows.op == OPS.index("rmw_read")] if len(rows) else np.zeros(0, np.int64)
    else:
        parts = [g.thread_ids() for g in source.groups if g.op == "rmw_read"]
        threads = np.concatenate(parts) if parts else np.zeros(0, np.int64)
    threads = np.unique(threads)
    return len(threads), len(np.unique(work.frag_pixel[threads])) if len(threads) else 0


def run_analytic(work, gpu, result=None, reference=None) -> tuple[dict, None]:
    """Bounds from the scheme's operation groups (no OpStream, no events); see gpusim.hw.analytic."""
    from gpusim.hw.analytic import analytic_timing
    start = time.perf_counter()
    rec = analytic_timing(result, work, gpu)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, rec.pop("total")), None


def _on_workload(run, name: str):
    def level(result, trace, gpu, reference=None, progress=None):
        if run is run_full:
            return run(Workload.of(result, trace), gpu, result, reference, progress=progress)
        return run(Workload.of(result, trace), gpu, result, reference)
    level.__name__ = f"{name}_timing"
    return level


def _thesis(result, trace=None, gpu=None, reference=None, progress=None):
    return thesis_timing(result), None


#: the fidelity levels by name: ``level(result, trace, gpu, reference, progress=None) -> (record, timed image or
#: None)``; the full level counts warps done on ``progress`` (a tqdm-like bar)
FIDELITIES = {"analytic": _on_workload(run_analytic, "analytic"), "sampled": _on_workload(run_sampled, "sampled"),
              "full": _on_workload(run_full, "full"), "thesis": _thesis}
