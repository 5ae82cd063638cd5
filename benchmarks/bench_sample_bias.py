"""Where the sampled level's cycle error comes from: its traffic against the full level's, per scheme.

    .venv/bin/python benchmarks/bench_sample_bias.py [--scene foliage] [--size 384] [--gpu gtx280]
        [--schemes tfss,zbuffer] [--gpu-set raster.warp_packing=tiles] [--report FILE]

For each scheme it runs the full and the sampled level on one scene and prints, as ratios of the
sampled record over the full one (each sampled figure is already scaled up to the whole run):
cycles, the coalescer's requests and bytes, the ROPs' operations, DRAM requests and busy cycles,
and, where the GPU has an L2, its misses. The column "cycles, operations' bytes" reruns the sample
with ``sample.run_traffic = false``: the memory partitions' load from the rest of the GPU scaled
from the sample's own coalesced traffic by its operations' bytes, not set from the run's coalesced
bytes, and so the bias of how a replicate's warps coalesce (DRAM busier than the run's where its
warps pack fragments of far-apart tiles). It is a dash for a run the sampled level takes whole.
Ratios near 1 in the traffic columns but not in the cycles column point at the cut-down machine
(queueing, a pass's tail); a traffic column off by about as much as the cycles points at the
sample's own work (how its warps coalesce, which lines it misses). The last columns give the
replicates' SMs and the speed-up over full. docs/timing-model.md ("The sampled level") quotes
the figures this gives on foliage at 384x384.

Each run is in this process, one after the other (``runner.workers = 1``).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpusim.atomic_io import write_text_atomic  # noqa: E402
from gpusim.errors import GpusimError  # noqa: E402
from gpusim.hw import load_gpu  # noqa: E402
from gpusim.replay import run_functional, run_timing  # noqa: E402
from gpusim.scene import load_scene, trace_scene  # noqa: E402
from gpusim.schemes import scheme_names  # noqa: E402

#: (column, unit, figure): the figures compared, each read from a timing record's ``units``
FIGURES = (("coalescer requests", "coalescer", "requests"), ("coalescer bytes", "coalescer", "bytes"),
           ("ROP operations", "rop", "requests"), ("DRAM requests", "dram", "requests"),
           ("DRAM busy", "dram", "busy_cycles"), ("L2 misses", "l2", "misses"))


def compare(result, trace, gpu, reference) -> dict:
    """The timing records of one scheme's ``result``: "full", "sampled" and, where the level samples, "ops"
    (the sample with ``sample.run_traffic = false``); or {"error": ...} for a run over
    ``runner.max_operations``."""
    records = {}
    for level, g in (("full", gpu), ("sampled", gpu),
                     ("ops", gpu.replace(sample=dataclasses.replace(gpu.sample, run_traffic=False)))):
        if level == "ops" and records["sampled"].get("sample", {}).get("sms", 0) >= gpu.core.sms:
            break                         # the run taken whole: nothing to scale
        try:
            records[level] = run_timing(result, trace, "full" if level == "full" else "sampled", g, reference)[0]
        except GpusimError as exc:
            return {"error": str(exc).split(" (")[0]}          # a run over runner.max_operations
    return records


def ratio(sampled, full) -> str:
    """``sampled / full`` to three places; a dash where either is missing or the full figure is 0."""
    if sampled is None or full is None or not full:
        return "-"
    return f"{sampled / full:.3f}"


def row(scheme: str, full: dict, sampled: dict, ops: dict | None) -> list[str]:
    cells = [scheme, ratio(sampled["cycles"], full["cycles"]),
             ratio(ops["cycles"], full["cycles"]) if ops is not None else "-"]
    for _, unit, stat in FIGURES:
        cells.append(ratio(sampled["units"].get(unit, {}).get(stat), full["units"].get(unit, {}).get(stat)))
    sms = sorted(set(sampled.get("sample", {}).get("replicate_sms", [])))
    cells.append("/".join(str(s) for s in sms) or "-")
    cells.append(f"{full['wall_seconds'] / max(sampled['wall_seconds'], 1e-9):.1f}x")
    return cells


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="foliage", help="built-in scene (default foliage)")
    ap.add_argument("--size", type=int, default=384, help="screen width and height in pixels (default 384)")
    ap.add_argument("--gpu", default="gtx280", help="GPU preset or .toml file (default gtx280)")
    ap.add_argument("--gpu-set", action="append", default=[], metavar="KEY=VALUE",
                    help="GPU config override for both levels (repeatable)")
    ap.add_argument("--schemes", default="", help="comma-separated schemes (default: every registered one)")
    ap.add_argument("--report", type=Path, help="also write the table to this markdown file")
    args = ap.parse_args(argv)
    schemes = [s for s in args.schemes.split(",") if s] or scheme_names()
    gpu = load_gpu(args.gpu, [*args.gpu_set, "runner.workers=1"])
    trace = trace_scene(*load_scene(args.scene, [f"screen.width={args.size}", f"screen.height={args.size}"]),
                        progress=False)
    title = (f"sampled over full on {args.scene} {args.size}x{args.size} ({len(trace):,} fragments), {gpu.name}"
             + (f", {' '.join(args.gpu_set)}" if args.gpu_set else ""))
    head = ["scheme", "cycles", "cycles, operations' bytes", *(name for name, _, _ in FIGURES), "replicate SMs",
            "speed-up"]
    lines = [f"# {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    print("\n".join(lines), flush=True)
    start = time.perf_counter()
    for scheme in schemes:
        result, _, reference = run_functional(trace, scheme, {})
        records = compare(result, trace, gpu, reference)
        line = ("| " + " | ".join(row(scheme, records["full"], records["sampled"], records.get("ops")))
                + " |" if "error" not in records
                else f"| {scheme} | {records['error']} |" + " |" * (len(head) - 2))
        lines.append(line)
        print(line, flush=True)
    lines += ["", f"{len(schemes)} schemes in {time.perf_counter() - start:.0f} s."]
    print(lines[-1])
    if args.report:
        write_text_atomic(args.report, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
