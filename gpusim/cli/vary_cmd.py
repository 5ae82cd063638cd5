"""``gpusim vary``: one scheme, one trace, one parameter swept over values; a table of what changes."""

from __future__ import annotations

from pathlib import Path

from gpusim.atomic_io import write_text_atomic
from gpusim.cli.common import print_json
from gpusim.config import parse_override
from gpusim.errors import ConfigError
from gpusim.replay import parse_params, replay
from gpusim.trace_io import load_trace


def add_parser(sub) -> None:
    p = sub.add_parser("vary", help="sweep one scheme parameter over values on one trace; print or write a table",
                       description="Replay TRACE through --scheme once per value of --vary KEY=V1,V2,... and "
                                   "tabulate the chosen stats, the image error and the footprint.")
    p.add_argument("trace", help="trace file (.npz)")
    p.add_argument("--scheme", required=True, metavar="NAME", help="scheme name (see 'gpusim schemes')")
    p.add_argument("--vary", required=True, metavar="KEY=V1,V2,...", help="parameter and its values")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE", help="fixed scheme parameter")
    p.add_argument("--stat", action="append", default=[], metavar="NAME",
                   help="scheme stat to tabulate (repeatable; default: all numeric stats)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p.add_argument("-o", "--output", metavar="FILE.md", help="write the table as markdown (atomically)")
    p.set_defaults(run=run)


def run(args) -> int:
    key, _, values = args.vary.partition("=")
    if not key or not values:
        raise ConfigError(f"--vary {args.vary}: give KEY=V1,V2,... e.g. --vary depth_filter=3,8,12")
    trace = load_trace(args.trace)
    fixed = parse_params(args.param)
    if key in fixed:
        raise ConfigError(f"--vary {key} is also given as --param {key}; give it once")
    rows = []
    for text in values.split(","):
        value = parse_override(f"{key}={text.strip()}")[1]
        _, record, _, _ = replay(trace, args.scheme, fixed | {key: value})
        stats = record["stats"]
        names = args.stat or [k for k, v in stats.items() if isinstance(v["value"], (int, float))]
        missing = [s for s in names if s not in stats]
        if missing:
            raise ConfigError(f"--stat {missing[0]}: {args.scheme} has no such stat (valid: {', '.join(stats)})")
        rows.append({key: value, **{s: stats[s]["value"] for s in names},
                     "differing_pixels": record["error"]["differing_pixels"], "rmse": record["error"]["rmse"],
                     "footprint_bytes": record["footprint_bytes"]["total"], "wall_seconds": record["wall_seconds"]})
    if args.json:
        print_json(rows)
    else:
        print(_markdown(rows))
    if args.output:
        head = (f"# {args.scheme}: {key} swept on {trace.meta.get('scene') or args.trace}\n\n"
                f"Trace `{args.trace}`: {len(trace):,} fragments on {trace.width}x{trace.height} pixels. "
                f"Fixed parameters: {', '.join(f'{k}={v}' for k, v in fixed.items()) or 'defaults'}. "
                "`differing_pixels` and `rmse` are against the exact reference (float64 sorted compositing); "
                "`wall_seconds` is the functional model's run time on the machine that wrote this file.\n\n")
        write_text_atomic(Path(args.output), head + _markdown(rows) + "\n")
    return 0


def _markdown(rows: list[dict]) -> str:
    cols = list(rows[0])
    fmt = lambda v: f"{v:.4g}" if isinstance(v, float) else f"{v:,}" if isinstance(v, int) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt(r[c]) for c in cols) + " |" for r in rows]
    return "\n".join(lines)
