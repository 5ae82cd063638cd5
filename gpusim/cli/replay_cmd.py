"""``gpusim replay``: run a trace through a multi-fragment scheme and report what it costs."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from gpusim.atomic_io import atomic_folder, write_text_atomic
from gpusim.cli.common import check_output, counted, print_json
from gpusim.errors import GpusimError
from gpusim.hw import DEFAULT_GPU, FIDELITIES, gpu_presets, load_gpu
from gpusim.replay import jsonable, parse_params, replay
from gpusim.schemes import scheme_names
from gpusim.trace_io import load_trace


def add_parser(sub) -> None:
    p = sub.add_parser("replay", help="replay a trace through a scheme: image, footprint, accesses, error",
                       description="Replay a fragment trace through one multi-fragment scheme (functional model) "
                                   "and report its footprint, memory accesses, passes, dropped fragments and "
                                   "image error against the exact reference. Schemes: " + ", ".join(scheme_names()))
    p.add_argument("trace", help="trace file (.npz)")
    p.add_argument("--scheme", required=True, metavar="NAME", help="scheme name (see 'gpusim schemes')")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="scheme parameter (repeatable), e.g. --param layers=8")
    p.add_argument("--fidelity", choices=sorted(FIDELITIES), metavar="LEVEL",
                   help="also run a timing model: analytic (bounds from work/throughput), sampled (event model "
                        "on replicate samples of the work on a GPU cut down to a share of its SMs, with a 95%% "
                        "confidence interval), full (event model on everything, RMW hazards replayed "
                        "into the image) or thesis (seed 003 section 4.3.2, for tfss, r-buffer and weight-factor)")
    p.add_argument("--gpu", metavar="PRESET|FILE", default=None,
                   help=f"GPU for the timing model: a preset ({', '.join(gpu_presets())}) or a .toml file "
                        f"(default {DEFAULT_GPU})")
    p.add_argument("--gpu-set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a GPU config key (repeatable), e.g. --gpu-set rop.reorder_entries=16")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--no-progress", action="store_true", help="never show the full level's progress bar")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="write image.png, difference.png and stats.json to DIR")
    p.set_defaults(run=run)


def _mib(n: int) -> str:
    return f"{n / 2**20:,.2f} MiB" if n >= 2**20 else f"{n / 1024:,.1f} KiB" if n >= 1024 else f"{n} B"


def _value(value) -> str:
    """A stat value as text: numbers with thousands separators, tables as NAME=VALUE pairs, lists in [ ]."""
    if isinstance(value, dict):
        return ", ".join(f"{k}={_value(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:,}"
    return str(value)


def check_gpu_arg(spec: str | None) -> None:
    """Refuse a ``--gpu`` that names a directory, a special file (a FIFO would block the read) or a missing
    path, saying so, before it could be taken for an unknown preset name."""
    if spec is None or spec in gpu_presets():
        return
    path = Path(spec)
    presets = f"or a preset ({', '.join(gpu_presets())})"
    if path.is_dir():
        raise GpusimError(f"--gpu {spec}: is a directory, not a GPU file; give a GPU .toml file {presets}")
    if path.exists() and not path.is_file():
        raise GpusimError(f"--gpu {spec}: not a regular file (a device, FIFO or socket); give a GPU .toml "
                          f"file {presets}")
    if not path.exists() and os.sep in spec and path.suffix != ".toml":
        raise GpusimError(f"--gpu {spec}: no such GPU file; check the path, or give a preset "
                          f"({', '.join(gpu_presets())})")


def run(args) -> int:
    if (args.gpu or args.gpu_set) and not args.fidelity:
        raise GpusimError("--gpu-set/--gpu need --fidelity LEVEL: only a timing model uses the GPU; "
                          "add e.g. --fidelity analytic, or drop --gpu/--gpu-set")
    check_gpu_arg(args.gpu)
    out = check_output(args.output, folder=True) if args.output else None
    trace = load_trace(args.trace)
    params = parse_params(args.param)
    gpu = load_gpu(args.gpu, args.gpu_set) if args.fidelity else None
    from tqdm import tqdm
    with tqdm(total=0, unit="warp", unit_scale=True, file=sys.stderr, dynamic_ncols=True, leave=False,
              disable=True if args.no_progress else None, desc="full level") as bar:   # on a terminal only
        result, record, image, reference = replay(trace, args.scheme, params, args.fidelity, gpu, bar)
    text = None if args.json else _text(args, record)    # formatted before anything is written
    if out is not None:
        _write_outputs(out, record, image, reference, result.extras.get("timed_image"))
    if args.json:
        print_json(record)
    else:
        print(text)
    return 0


def _differ(n: int) -> str:
    return f"{counted(n, 'pixel')} {'differs' if n == 1 else 'differ'}"


def _text(args, record: dict) -> str:
    """The text report of a replay record."""
    lines: list[str] = []
    add = lines.append
    e = record["error"]
    add(f"scheme       {record['scheme']}  " + " ".join(f"{k}={v}" for k, v in record["params"].items()))
    add(f"trace        {args.trace}: {counted(record['fragments'], 'fragment')} on "
        f"{counted(record['pixels'], 'pixel')}")
    add(f"passes       {record['geometry_passes']} geometry; "
        + ", ".join(p["name"] for p in record["passes"][:8]) + (" ..." if len(record["passes"]) > 8 else ""))
    add("footprint    structure          allocated       used")
    for name, size in record["footprint_bytes"].items():
        add(f"             {name:<16} {_mib(size):>12} {_mib(record['footprint_used_bytes'][name]):>12}")
    add("accesses     structure          operation      count")
    for name, ops in record["accesses"].items():
        for op, count in ops.items():
            add(f"             {name:<16} {op:<12} {count:>12,}")
    add(f"dropped      {counted(record['dropped_fragments'], 'fragment')} "
        f"({counted(record['overflowed_pixels'], 'pixel')} lost some)")
    for name, stat in record["stats"].items():
        add(f"stat         {name} = {_value(stat['value'])} {stat['unit']}  ({stat['doc']})")
    psnr = "inf" if e["psnr"] == float("inf") else f"{e['psnr']:.2f}"
    add(f"error        rmse {e['rmse']:.3g}, psnr {psnr} dB, {_differ(e['differing_pixels'])} "
        f"by more than one 8-bit step")
    if "timing" in record:
        _timing_text(record["timing"], add)
    add(f"wall         {record['wall_seconds']:.3f} s (functional model)")
    if args.output:
        add(f"wrote        {args.output}/image.png, difference.png, stats.json")
    return "\n".join(lines)


def _timing_text(t: dict, add) -> None:
    """The timing lines of a replay record, each passed to ``add``."""
    if t["fidelity"] == "thesis":
        add(f"cycles       {t['cycles']:,} ({t['fidelity']}: {t['memory_cycles']:,} memory + "
            f"{t['compute_cycles']:,} compute, {t['compute_formula']} per pixel)")
        return
    add(f"cycles       {t['cycles']:,} ({t['fidelity']} on {t['gpu']}: {t['microseconds']:,.1f} us; "
        f"{counted(t['instructions'], 'warp instruction')}, {t['wall_seconds']:.2f} s)")
    if "cycles_ci95_low" in t and t["sample"]["share"] >= 1:
        s = t["sample"]
        add(f"  95% CI     {t['cycles_ci95_low']:,} to {t['cycles_ci95_high']:,} cycles (the whole run, simulated "
            f"once: its {counted(s['tiles'], 'tile')} are too few for {s['replicates']} replicates of at least "
            f"sample.min_tiles = {s['min_tiles']} to cost less)")
    elif "cycles_ci95_low" in t:
        s = t["sample"]
        check = s.get("scale_check")
        scale = (f"; machine-size bias {check['bias_estimate'] / t['cycles']:+.2%} from replicates 0 and 1 "
                 f"together on {counted(check['sms'], 'SM')}" if check and t["cycles"] else "")
        what = "the replicates' standard error and the machine-size bias" if check else "standard error"
        thin = (f", thinned to {s['thin']:.0%} of their SMs' work and extrapolated to the whole by the work checks"
                if s.get("work_check") else "")
        add(f"  95% CI     {t['cycles_ci95_low']:,} to {t['cycles_ci95_high']:,} cycles (error estimate "
            f"{t['cycle_error_estimate']:.1%}: {what} over "
            f"the cycles, from {counted(s['replicates'], 'replicate')} of {counted(s['sms'], 'SM')} each, "
            f"{s['tiles_per_replicate']:,} of {counted(s['tiles'], 'tile')}{thin}{scale})")
    if "cycles_ci95_low" in t and t["sample"].get("wall_seconds"):
        w = t["sample"]["wall_seconds"]
        total = sum(w.values()) or 1.0
        add(f"  wall       {w['run']:.2f} s on the whole run (its operations counted, its traffic sampled), "
            f"{w['programs']:.2f} s lowering the samples, {w['events']:.2f} s replaying them "
            f"({w['events'] / total:.0%} of the level's time)")
    for p in t["passes"][:12]:
        extra = f"  bound: {p['bound']}" if "bound" in p else ""
        add(f"  pass       {p['name']:<20} {p['cycles']:>14,} cycles  {p['warps']:>8,} warps{extra}")
    if len(t["passes"]) > 12:
        add(f"  pass       ... {len(t['passes']) - 12} more")
    if t.get("repeated_passes"):
        n = t["repeated_passes"]
        add(f"  note       {counted(n, 'pass', 'passes')} {'repeats' if n == 1 else 'repeat'} an earlier pass's work "
            "(each group within 1% of its threads): timed once, counted each time")
    if t.get("interpolated_passes"):
        n = t["interpolated_passes"]
        add(f"  note       {counted(n, 'pass', 'passes')} of long families whose threads only shrink "
            f"{'is' if n == 1 else 'are'} interpolated between timed passes (each bound on a straight line, "
            "checked at the midpoint)")
    for name, u in t["units"].items():
        if "utilisation_mean" in u:
            add(f"  unit       {name:<10} utilisation mean {u['utilisation_mean']:.1%}"
                + (f", max {u['utilisation_max']:.1%}" if "utilisation_max" in u else ""))
        else:
            add(f"  unit       {name:<10} {counted(u.get('requests', 0), 'request')}")
    if t.get("rmw_hazards") is not None:
        line = (f"{counted(t['rmw_hazards'], 'fragment')} read an obsolete value "
                f"({counted(t['rmw_hazard_pixels'], 'pixel')})")
        if "rmw_image_error" in t:
            e = t["rmw_image_error"]
            line += f"; image in event order: rmse {e['rmse']:.3g}, {_differ(e['differing_pixels'])}"
        add(f"rmw hazards  {line}")


def _write_outputs(out: Path, record: dict, image, reference, timed=None) -> None:
    """The output files, moved into ``out`` together once all are written."""
    from gpusim.report.images import save_heatmap_png, save_image_png

    diff = np.abs(np.asarray(image) - reference).max(axis=2)
    with atomic_folder(out) as tmp:
        save_image_png(image, tmp / "image.png")
        if timed is not None:
            save_image_png(timed, tmp / "image-timed.png")
        save_heatmap_png(diff, tmp / "difference.png",
                         title=f"{record['scheme']}: |image - reference| (max channel)", label="absolute difference")
        write_text_atomic(tmp / "stats.json", json.dumps(jsonable(record), indent=2) + "\n")
