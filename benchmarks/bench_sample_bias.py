"""Where the sampled level's cycle error comes from: its traffic against the full level's, per scheme.

    .venv/bin/python benchmarks/bench_sample_bias.py [--scene foliage] [--size 384] [--gpu gtx280]
        [--schemes tfss,zbuffer] [--gpu-set raster.warp_packing=tiles] [--report FILE]

For each scheme it runs the full and the sampled level on one scene and prints, as ratios of the
sampled record over the full one (each sampled figure is already scaled up to the whole run):
cycles, the coalescer's requests and bytes, the ROPs' operations, DRAM requests and busy cycles,
and, where the GPU has an L2, its misses. The column "cycles, run's DRAM bytes" reruns the sample
with each DRAM request holding its partition as long as the full run's coalesced bytes over the
sample's, per pass and partition: an oracle taken from the full run, not something the sampled
level can know, giving the error were the replicate's DRAM load exactly the run's. It is a dash
on a GPU with an L2 (the memory levels share that factor) and for a run streamed in chunks.
Ratios near 1 in the traffic columns but not in the cycles column point at the cut-down machine
(queueing, a pass's tail); a traffic column off by about as much as the cycles points at the
sample's own work (how its warps coalesce, which lines it misses). The last columns give the
replicates' SMs and the speed-up over full. docs/timing-model.md ("The sampled level") quotes
the figures this gives on foliage at 384x384.

Each run is in this process, one after the other (``runner.workers = 1``): the full and sampled
levels of every scheme on foliage's 1.7M fragments took 22 minutes of one core on the 2-core
reference machine; the oracle runs each sample once more, about a sixth more time on that case.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpusim.atomic_io import write_text_atomic  # noqa: E402
from gpusim.errors import GpusimError  # noqa: E402
from gpusim.hw import load_gpu  # noqa: E402
from gpusim.hw.memory.dram import DramChannel  # noqa: E402
from gpusim.replay import run_functional, run_timing  # noqa: E402
from gpusim.scene import load_scene, trace_scene  # noqa: E402
from gpusim.schemes import scheme_names  # noqa: E402

#: (column, unit, figure): the figures compared, each read from a timing record's ``units``
FIGURES = (("coalescer requests", "coalescer", "requests"), ("coalescer bytes", "coalescer", "bytes"),
           ("ROP operations", "rop", "requests"), ("DRAM requests", "dram", "requests"),
           ("DRAM busy", "dram", "busy_cycles"), ("L2 misses", "l2", "misses"))


def dram_bytes(channel: DramChannel, chunks) -> np.ndarray:
    """The bytes of a program's DRAM requests, per (pass, partition)."""
    prog, P = channel.program, channel.instances
    n = len(prog.passes)
    out = np.zeros(n * P)
    for q in chunks:
        out += np.bincount(prog.wi_pass[q.wi] * P + q.partition, weights=q.nbytes, minlength=n * P)
    return out.reshape(n, P)


@contextlib.contextmanager
def dram_load(record: dict, mode: str | None):
    """While inside, each DRAM channel built: with ``mode = "record"`` (a full run) records its program's
    bytes per (pass, partition) in ``record["bytes"]``; with ``"exact"``, a sampled program's "memory"
    occupancy becomes the recorded run's bytes over its own (the oracle); None leaves them as they are."""
    prepare = DramChannel.prepare

    def wrapped(channel, chunks, write):
        prog = channel.program
        if mode == "record":
            record["bytes"] = dram_bytes(channel, chunks)
        elif mode == "exact" and prog.occupancy is not None:
            run, mine = record["bytes"], dram_bytes(channel, chunks)
            if run.shape != mine.shape:
                raise GpusimError("the oracle needs the sample and the run in one program of the same passes")
            prog.occupancy = dict(prog.occupancy) | {"memory": np.where(mine > 0, run / np.maximum(mine, 1e-9),
                                                                         1.0)}
        return prepare(channel, chunks, write)

    DramChannel.prepare = wrapped
    try:
        yield
    finally:
        DramChannel.prepare = prepare


def compare(result, trace, gpu, reference) -> dict:
    """The timing records of one scheme's ``result``: "full", "sampled" and, where the oracle applies,
    "exact" (the sample with the run's DRAM bytes, :func:`dram_load`); or {"error": ...} for a run
    over ``runner.max_operations``."""
    records, load = {}, {}
    for level, mode in (("full", "record"), ("sampled", None), ("exact", "exact")):
        if mode == "exact" and ("l2" in records["full"]["units"] or "dram" not in records["full"]["units"]):
            break                         # the L2 shares the factor; or no DRAM traffic to set
        try:
            with dram_load(load, mode):
                records[level] = run_timing(result, trace, "full" if level == "full" else "sampled", gpu,
                                            reference)[0]
        except GpusimError as exc:
            if mode == "exact":           # a run streamed in chunks: no oracle, a dash
                break
            return {"error": str(exc).split(" (")[0]}          # a run over runner.max_operations
    return records


def ratio(sampled, full) -> str:
    """``sampled / full`` to three places; a dash where either is missing or the full figure is 0."""
    if sampled is None or full is None or not full:
        return "-"
    return f"{sampled / full:.3f}"


def row(scheme: str, full: dict, sampled: dict, exact: dict | None) -> list[str]:
    cells = [scheme, ratio(sampled["cycles"], full["cycles"]),
             ratio(exact["cycles"], full["cycles"]) if exact is not None else "-"]
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
    head = ["scheme", "cycles", "cycles, run's DRAM bytes", *(name for name, _, _ in FIGURES), "replicate SMs",
            "speed-up"]
    lines = [f"# {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    print("\n".join(lines), flush=True)
    start = time.perf_counter()
    for scheme in schemes:
        result, _, reference = run_functional(trace, scheme, {})
        records = compare(result, trace, gpu, reference)
        line = ("| " + " | ".join(row(scheme, records["full"], records["sampled"], records.get("exact")))
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
