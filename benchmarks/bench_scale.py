"""Scale: the stress scenes and a 20M-fragment frame through every scheme and fidelity level.

    .venv/bin/python benchmarks/bench_scale.py                     # both parts (about 30 minutes on 2 cores)
    .venv/bin/python benchmarks/bench_scale.py --part stress --scheme kbuffer --level analytic
    .venv/bin/python benchmarks/bench_scale.py --part big --no-full

Every run is timed in a child process of its own (one per scene and scheme), which reports its
peak resident memory (``ru_maxrss``); each child first replays a tiny trace through the same
scheme and levels, so imports and first calls are not timed. Times are CPU seconds of the child
(user + system: what other work on a shared machine disturbs least) with wall seconds beside them.
In the stress part a call shorter than 2 s of CPU is made up to ``--repeat`` times (default 3), the
fastest counting, and each scheme's baseline and stress runs follow one another, so the machine's
drift over the part's minutes does not enter a ratio.

1. Stress scenes (issue 18): ``stress-layers``, ``coplanar``, ``alpha-extremes`` and ``slivers`` at
   their bundled sizes, and the ``default`` scene at its bundled 512x512 as the baseline, through
   every scheme at every level: ``none`` (the functional model), ``analytic``, ``sampled``, ``full``,
   on ``gtx280`` (``runner.workers = 1``). Printed per run: microseconds per fragment and its ratio
   to the default scene's for the same scheme and level; a refusal (``R``) is checked to be one line
   whose advice (``--fidelity analytic``) then works. Targets: every ratio at most 10x; on
   ``stress-layers`` the analytic level finishes for every scheme, sampled and full finish or refuse
   with working advice, all with peak memory under 4 GiB. The analytic level's passes that repeat
   an earlier pass's work (depth peeling's once one pixel is left) are timed once and counted again:
   their number is printed.
2. A 1920x1080 frame of >= 20M fragments (``dense-foliage``, bundled): traced, then replayed through
   every scheme functionally and at the analytic level (the exact reference image, which every
   replay's image error needs, is made once). The schemes run ``--jobs`` processes at a time (default:
   one per CPU), as ``gpusim run`` spreads a sweep. Targets: the wall time from the trace's start to
   the last scheme's end under 5 minutes on the machine's cores (2 on the reference machine), each
   process's peak memory under 8 GiB; the full level for ``freepipe-abuffer`` under 2 minutes of CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

STRESS = ("stress-layers", "coplanar", "alpha-extremes", "slivers")
BASELINE = "default"
BIG = "dense-foliage"
LEVELS = ("none", "analytic", "sampled", "full")
GPU = ("gtx280", ["runner.workers=1"])
RATIO = 10.0                   # stress scene's time per fragment / the default scene's, at most
STRESS_MEMORY = 4 * 2**30      # bytes
BIG_MEMORY = 8 * 2**30
BIG_SECONDS = 300.0            # trace + every scheme functional + analytic
BIG_FULL_SECONDS = 120.0       # freepipe-abuffer at the full level
BIG_FULL_SCHEME = "freepipe-abuffer"
MIN_FRAGMENTS = 20_000_000
W = 31                         # the scheme column
REPEAT_BELOW = 2.0             # CPU seconds: a stress-part call shorter than this is repeated (--repeat)


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _peak() -> int:
    """This process's peak resident memory in bytes (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _timed(fn):
    """(result or the GpusimError it raised, wall seconds, CPU seconds)."""
    from gpusim.errors import GpusimError
    wall, cpu = time.perf_counter(), _cpu()
    try:
        out = fn()
    except GpusimError as exc:
        out = exc
    return out, time.perf_counter() - wall, _cpu() - cpu


def _best(fn, repeat: int, first=None, fresh=None):
    """:func:`_timed` of ``fn(first)``, called again (up to ``repeat`` calls in all) while a call takes under
    :data:`REPEAT_BELOW` CPU seconds: the fastest call's figures (a short run's time is mostly the
    machine's noise, which a single call on a shared 2-core machine shows as 2x from minute to minute).
    A repeat's argument is ``fresh()``, made untimed, so that no call finds what an earlier one cached on it
    (TFSS's addresses on its functional result)."""
    best = _timed(lambda: fn(first))
    for _ in range(repeat - 1):
        if best[2] >= REPEAT_BELOW:
            break
        arg = fresh() if fresh else first
        again = _timed(lambda: fn(arg))
        if again[2] < best[2]:
            best = again
    return best


def _level(result, trace, level: str, gpu, reference, repeat: int = 1, again=None) -> dict:
    """One timing level on a functional result: status, times, cycles, the analytic level's repeated passes.
    ``again()`` makes a fresh functional result for each call after the first (see :func:`_best`)."""
    from gpusim.errors import GpusimError
    from gpusim.replay import run_timing
    got, wall, cpu = _best(lambda r: run_timing(r, trace, level, gpu, reference), repeat, result, again)
    if isinstance(got, GpusimError):
        return {"status": "refused", "error": str(got), "wall": wall, "cpu": cpu}
    rec = got[0]
    return {"status": "ok", "wall": wall, "cpu": cpu, "cycles": rec["cycles"],
            "repeated_passes": sum(1 for p in rec.get("passes", []) if "repeat_of" in p),
            "interpolated_passes": sum(1 for p in rec.get("passes", []) if "interpolated" in p),
            "streamed": rec.get("streamed")}


def _warm_up(scheme: str, levels) -> None:
    """Imports and first calls, untimed: the scheme and levels on a tiny trace."""
    from gpusim.hw import load_gpu
    from gpusim.replay import run_functional
    from gpusim.scene import load_scene, trace_scene
    trace = trace_scene(*load_scene(BASELINE, ["screen.width=24", "screen.height=24"]), progress=False)
    result, _, reference = run_functional(trace, scheme, {})
    gpu = load_gpu(*GPU)
    for level in levels:
        if level != "none":
            _level(result, trace, level, gpu, reference)


def child_scene(job: dict) -> dict:
    """A bundled scene at its own size through one scheme at ``levels``."""
    from gpusim.hw import load_gpu
    from gpusim.replay import run_functional
    from gpusim.scene import load_scene, trace_scene
    _warm_up(job["scheme"], job["levels"])
    trace = trace_scene(*load_scene(job["scene"]), progress=False)
    gpu = load_gpu(*GPU)
    out = {"fragments": len(trace), "size": f"{trace.width}x{trace.height}", "levels": {}}
    repeat = job.get("repeat", 1)
    (result, _, reference), wall, cpu = _best(lambda _: run_functional(trace, job["scheme"], {}), repeat)
    out["levels"]["none"] = {"status": "ok", "wall": wall, "cpu": cpu, "passes": len(result.passes)}
    def fresh():
        return run_functional(trace, job["scheme"], {}, reference=reference)[0]

    for i, level in enumerate(lv for lv in job["levels"] if lv != "none"):
        # each level on a result of its own: none finds what another cached on it
        out["levels"][level] = _level(result if i == 0 else fresh(), trace, level, gpu, reference, repeat, fresh)
    return out


def child_trace(job: dict) -> dict:
    """Trace the big scene into ``job["dir"]``: the trace and its exact reference image."""
    import numpy as np
    from gpusim.metrics import composite_exact
    from gpusim.scene import load_scene, trace_scene
    from gpusim.trace_io import save_trace
    trace, wall, cpu = _timed(lambda: trace_scene(*load_scene(job["scene"]), progress=False))
    reference, rwall, rcpu = _timed(lambda: composite_exact(trace))
    save_trace(trace, Path(job["dir"]) / "trace.npz")
    np.save(Path(job["dir"]) / "reference.npy", reference)
    return {"fragments": len(trace), "size": f"{trace.width}x{trace.height}",
            "max_depth": int(trace.depth_complexity().max()), "trace": {"wall": wall, "cpu": cpu},
            "reference": {"wall": rwall, "cpu": rcpu}}


def child_big(job: dict) -> dict:
    """The saved big trace through one scheme at ``levels`` (its reference loaded, not made again)."""
    import numpy as np
    from gpusim.hw import load_gpu
    from gpusim.replay import run_functional
    from gpusim.trace_io import load_trace
    _warm_up(job["scheme"], job["levels"])
    trace, wall, cpu = _timed(lambda: load_trace(Path(job["dir"]) / "trace.npz"))
    reference = np.load(Path(job["dir"]) / "reference.npy")
    out = {"load": {"wall": wall, "cpu": cpu}, "levels": {}}
    (result, _, _), wall, cpu = _timed(lambda: run_functional(trace, job["scheme"], {}, reference=reference))
    out["levels"]["none"] = {"status": "ok", "wall": wall, "cpu": cpu, "passes": len(result.passes)}
    gpu = load_gpu(*GPU)
    for level in job["levels"]:
        if level != "none":
            out["levels"][level] = _level(result, trace, level, gpu, reference)
    return out


CHILDREN = {"scene": child_scene, "trace": child_trace, "big": child_big}


def run_child(job: dict, timeout: float) -> dict:
    """``job`` in a fresh process: its answer, with the process's peak memory (or how it failed)."""
    cmd = [sys.executable, __file__, "--child", json.dumps(job)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"failed": f"over the {timeout:.0f} s time limit"}
    lines = done.stdout.strip().splitlines()
    if done.returncode or not lines:
        tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
        return {"failed": f"exit status {done.returncode}: {tail[:200]}"}
    return json.loads(lines[-1])


def _us(entry: dict, fragments: int) -> float:
    return entry["cpu"] / fragments * 1e6


def stress(schemes, levels, scenes, timeout: float, repeat: int) -> bool:
    """Part 1; whether every target was met."""
    print(f"== Stress scenes against {BASELINE} (bundled sizes, gtx280, runner.workers = 1): CPU microseconds "
          f"per fragment (best of up to {repeat} calls for a call under {REPEAT_BELOW:g} s), and x = that / "
          f"{BASELINE}'s for the same scheme and level; R = refused in one line")
    got: dict[tuple[str, str], dict] = {}
    for scheme in schemes:                # a scheme's baseline and stress runs close together in time
        for scene in (BASELINE, *scenes):
            got[scene, scheme] = run_child({"kind": "scene", "scene": scene, "scheme": scheme, "levels": levels,
                                            "repeat": repeat}, timeout)
    ok = True
    worst: list[tuple[float, str]] = []
    problems: list[str] = []
    for scene in (BASELINE, *scenes):
        first = next((g for (s, _), g in got.items() if s == scene and "fragments" in g), {})
        print(f"\n{scene} ({first.get('size', '?')}, {first.get('fragments', 0):,} fragments)")
        print(f"{'scheme':<{W}}" + "".join(f"{lv:>30}" for lv in levels) + f"{'peak MB':>9}")
        for scheme in schemes:
            g = got[scene, scheme]
            if "failed" in g:
                print(f"{scheme:<{W}}FAILED: {g['failed']}")
                problems.append(f"{scene} {scheme}: {g['failed']}")
                ok = False
                continue
            base = got.get((BASELINE, scheme), {})
            cells = []
            for level in levels:
                e = g["levels"][level]
                b = base.get("levels", {}).get(level) if "levels" in base else None
                if e["status"] == "refused":
                    one_line = "\n" not in e["error"] and "--fidelity analytic" in e["error"]
                    works = g["levels"].get("analytic", {}).get("status") == "ok"
                    cells.append("R" + ("" if one_line and works else "(advice FAILS)"))
                    if not (one_line and works) or level in ("none", "analytic"):
                        problems.append(f"{scene} {scheme} {level}: refused: {e['error'][:160]}")
                    continue
                us = _us(e, g["fragments"])
                text = f"{us:9.2f}"
                if scene != BASELINE and b is not None and b["status"] == "ok":
                    ratio = us / _us(b, base["fragments"])
                    worst.append((ratio, f"{scene} {scheme} {level}"))
                    text += f" {ratio:6.1f}x"
                marks = [f"{e[k]} {short}" for k, short in (("repeated_passes", "rep"), ("interpolated_passes", "int"))
                         if e.get(k)]
                if marks:
                    text += f" [{', '.join(marks)}]"
                cells.append(text)
            print(f"{scheme:<{W}}" + "".join(f"{c:>30}" for c in cells) + f"{g['peak'] / 2**20:9,.0f}")
    print("\n[N rep, M int]: N passes repeat an earlier pass's work, the analytic level timing them once and "
          "counting them again; M passes of long shrinking families it interpolates between timed passes")
    if "stress-layers" in scenes:
        layers = [got["stress-layers", s] for s in schemes if "levels" in got["stress-layers", s]]
        peak = max((g["peak"] for g in layers), default=0)
        finished = all(g["levels"].get("analytic", {"status": "ok"})["status"] == "ok" for g in layers)
        answered = len(layers) == len(schemes) and not any(p.startswith("stress-layers") for p in problems)
        met = peak < STRESS_MEMORY and finished and answered
        print(f"target stress-layers: analytic finishes for every scheme, sampled/full finish or refuse with "
              f"working advice, peak memory {peak / 2**30:.2f} GiB < 4 GiB: {'met' if met else 'MISSED'}")
        ok &= met
    worst.sort(reverse=True)
    over = [w for w in worst if w[0] > RATIO]
    print(f"target every stress run <= {RATIO:g}x the default scene's time per fragment: "
          + ("met" if not over else "MISSED") + (f" (largest {worst[0][0]:.1f}x: {worst[0][1]})" if worst else ""))
    for ratio, what in over:
        print(f"  {ratio:6.1f}x {what}")
    for p in problems:
        print(f"  problem: {p}")
    return ok and not over and not problems


def big(schemes, scene: str, full: bool, timeout: float, jobs: int) -> bool:
    """Part 2; whether every target was met."""
    print(f"\n== The large frame: {scene} ({jobs} scheme processes at a time)")
    ok = True
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp:
        began = time.perf_counter()
        t = run_child({"kind": "trace", "scene": scene, "dir": tmp}, timeout)
        if "failed" in t:
            print(f"tracing FAILED: {t['failed']}")
            return False
        n = t["fragments"]
        print(f"{t['size']}, {n:,} fragments (target >= {MIN_FRAGMENTS:,}), depth complexity up to "
              f"{t['max_depth']}; trace {t['trace']['cpu']:.1f} s CPU ({t['trace']['wall']:.1f} s wall), exact "
              f"reference {t['reference']['cpu']:.1f} s CPU ({t['reference']['wall']:.1f} s); peak "
              f"{t['peak'] / 2**20:,.0f} MB")
        total = t["trace"]["cpu"] + t["reference"]["cpu"]
        peak = t["peak"]
        print(f"{'scheme':<{W}}{'functional s':>14}{'analytic s':>12}{'wall s':>9}{'peak MB':>9}  analytic")
        with ThreadPoolExecutor(jobs) as pool:      # each job is a child process; the threads only wait on them
            got = pool.map(lambda s: run_child({"kind": "big", "dir": tmp, "scheme": s,
                                                "levels": ["none", "analytic"]}, timeout), schemes)
            for scheme, g in zip(schemes, got):
                if "failed" in g:
                    print(f"{scheme:<{W}}FAILED: {g['failed']}")
                    ok = False
                    continue
                f, a = g["levels"]["none"], g["levels"]["analytic"]
                total += f["cpu"] + a["cpu"]
                peak = max(peak, g["peak"])
                note = (f"{a['cycles']:,} cycles" + (f", {a['repeated_passes']} repeated passes" if a.get(
                    "repeated_passes") else "") + (f", {a['interpolated_passes']} interpolated" if a.get(
                    "interpolated_passes") else "")) if a["status"] == "ok" else f"REFUSED: {a['error'][:80]}"
                ok &= a["status"] == "ok"
                print(f"{scheme:<{W}}{f['cpu']:14.1f}{a['cpu']:12.1f}{f['wall'] + a['wall']:9.1f}"
                      f"{g['peak'] / 2**20:9,.0f}  {note}", flush=True)
        wall_total = time.perf_counter() - began
        met = wall_total < BIG_SECONDS and n >= MIN_FRAGMENTS
        print(f"target trace + every scheme functional and analytic < {BIG_SECONDS:.0f} s on {jobs} processes: "
              f"{wall_total:.0f} s wall, including each child's start and warm-up ({total:.0f} s CPU timed in the "
              f"children, {total / jobs:.0f} s spread over {jobs}): {'met' if met else 'MISSED'}")
        print(f"target peak memory < 8 GiB in every process: {peak / 2**30:.2f} GiB: "
              + ("met" if peak < BIG_MEMORY else "MISSED"))
        ok &= met and peak < BIG_MEMORY
        if full:
            g = run_child({"kind": "big", "dir": tmp, "scheme": BIG_FULL_SCHEME, "levels": ["full"]},
                          max(timeout, 4 * BIG_FULL_SECONDS))
            if "failed" in g:
                print(f"full level, {BIG_FULL_SCHEME}: FAILED: {g['failed']}")
                return False
            e = g["levels"]["full"]
            if e["status"] != "ok":
                print(f"full level, {BIG_FULL_SCHEME}: REFUSED: {e['error']}")
                return False
            streamed = e.get("streamed")
            how = (f"; streamed in {streamed['chunks']} chunks of passes" if streamed else "")
            met = e["cpu"] < BIG_FULL_SECONDS
            print(f"target full level for {BIG_FULL_SCHEME} < {BIG_FULL_SECONDS:.0f} s: {e['cpu']:.0f} s CPU "
                  f"({e['wall']:.0f} s wall), {e['cycles']:,} cycles, peak {g['peak'] / 2**20:,.0f} MB{how}: "
                  + ("met" if met else "MISSED"))
            ok &= met
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("stress", "big", "all"), default="all")
    ap.add_argument("--scheme", action="append", help="only this scheme (repeatable)")
    ap.add_argument("--level", action="append", choices=LEVELS[1:],
                    help="only this timing level, besides the functional model (repeatable)")
    ap.add_argument("--scene", action="append", choices=STRESS, help="only this stress scene (repeatable)")
    ap.add_argument("--big-scene", default=BIG, help="the large frame's scene (default: %(default)s)")
    ap.add_argument("--no-full", action="store_true", help=f"leave out the full level for {BIG_FULL_SCHEME} "
                    "on the large frame")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="the large frame's scheme processes run at a time (default: one per CPU, %(default)s)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds each child process may take")
    ap.add_argument("--repeat", type=int, default=3, help="stress part: calls of a level that takes under "
                    f"{REPEAT_BELOW:g} s of CPU, the fastest counting (default: %(default)s)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        job = json.loads(args.child)
        out = CHILDREN[job["kind"]](job)
        print(json.dumps(out | {"peak": _peak()}))
        return 0
    from gpusim.schemes import scheme_names
    schemes = args.scheme or scheme_names()
    levels = ["none", *(args.level or LEVELS[1:])]
    print(f"{os.cpu_count()} CPUs, load average {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    ok = True
    if args.part in ("stress", "all"):
        ok &= stress(schemes, levels, args.scene or list(STRESS), args.timeout, max(1, args.repeat))
    if args.part in ("big", "all"):
        ok &= big(schemes, args.big_scene, not args.no_full, args.timeout, max(1, args.jobs))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
