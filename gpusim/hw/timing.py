"""The fidelity levels of the timing model: ``analytic``, ``sampled``, ``full`` (and ``thesis``).

* ``full``: the event model (gpusim.hw.machine) on every operation.
* ``sampled`` (gpusim.hw.sample): the event model on replicate stratified
  samples of the work (screen tiles, triangle blocks, thread blocks), each on a
  GPU cut down to the sample's share of SMs, its other units kept whole and
  occupied as by the whole GPU's traffic; the replicates' mean, and from their
  spread a standard error and a 95% confidence interval of the cycles.
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
from gpusim.hw.lower import Workload, lower
from gpusim.hw.machine import Machine
from gpusim.hw.program import Program
from gpusim.hw.sample import run_sampled
from gpusim.hw.stream import StreamedRun, plan_chunks, run_streamed, unit_records
from gpusim.hw.thesis import thesis_timing


def _base(gpu, fidelity: str, instructions: int, n_ops: int) -> dict:
    return {"fidelity": fidelity, "gpu": gpu.name, "instructions": int(instructions), "operations": int(n_ops)}


def _finish(rec: dict, gpu, cycles: int) -> dict:
    rec["cycles"] = int(cycles)
    rec["microseconds"] = cycles / gpu.core.clock_mhz
    return rec


def _hazards(rec: dict, windows, work: Workload, result, reference):
    """RMW hazards from the event times (the RMW ``windows``, or None; a sample's: windows of its own threads,
    and those threads), and the image replayed in event order (a whole run's)."""
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = 0, 0
    if windows is None:
        return None
    read, write, *own = windows
    h, hp = count_hazards(work.frag_pixel[own[0]] if own else work.frag_pixel, read, write)
    rec["rmw_hazards"], rec["rmw_hazard_pixels"] = int(h), int(hp)
    replay = result.extras.get("rmw_replay") if result is not None and not own else None
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
    image = _hazards(rec, machine_windows(program, machine, len(work.frag_pixel), own=sampled), work,
                     None if sampled else result, reference)
    rec["event_seconds"] = time.perf_counter() - start
    return _finish(rec, gpu, total), image


def _run_streamed(work: Workload, gpu, chunks, result, reference, progress, start: float):
    """:func:`run_full` a chunk of passes at a time (gpusim.hw.stream); the same record, plus ``streamed``."""
    rec, image = streamed_record(work, gpu, run_streamed(work, gpu, chunks, progress), result, reference)
    rec["streamed"] = {"chunks": len(chunks), "passes": [list(c) for c in chunks]}
    rec["event_seconds"] = time.perf_counter() - start
    return rec, image


def streamed_record(work: Workload, gpu, run: StreamedRun, result=None, reference=None) -> tuple[dict, object]:
    """:func:`run_full`'s record of a run replayed a program at a time (``run``), and the image with its RMW
    artifacts or None."""
    total = sum(p[2] for p in run.passes)
    units = run.units(gpu)
    rec = _base(gpu, "full", run.instructions, run.operations)
    rec["passes"] = [{"name": name, "kind": kind, "cycles": c, "warps": warps} for name, kind, c, warps in run.passes]
    rec["units_built"] = list(units)
    rec["units"], rec["unit_stats"] = unit_records(units, total)
    image = _hazards(rec, run.windows(), work, result, reference)
    return _finish(rec, gpu, total), image


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
