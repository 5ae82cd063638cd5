"""``gpusim info``: what a trace holds."""

from __future__ import annotations

from gpusim.cli.common import counted, print_json
from gpusim.trace_info import bucket_histogram, describe
from gpusim.trace_io import load_trace


def add_parser(sub) -> None:
    p = sub.add_parser("info", help="fragments, covered pixels and depth complexity of a trace",
                       description="Summarise a fragment trace.")
    p.add_argument("trace", help="trace file (.npz)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.set_defaults(run=run)


def run(args) -> int:
    info = describe(load_trace(args.trace))
    if args.json:
        print_json({"file": args.trace, **info})
        return 0
    dc = info["depth_complexity"]
    scene = info["meta"].get("scene", "-")
    print(f"trace        {args.trace} (scene: {scene})")
    print(f"screen       {info['width']}x{info['height']} pixels")
    print(f"fragments    {info['fragments']:,} from {counted(info['primitives'], 'primitive')}")
    submitted = info["primitives_submitted"]
    if submitted is not None:
        print(f"primitives   {submitted:,} submitted; {submitted - info['primitives']:,} made no fragment (culled, "
              "clipped, off screen or between pixel centres)")
    print(f"transparent  {info['transparent_fragments']:,} ({100 * info['transparent_share']:.1f}%)")
    print(f"covered      {counted(info['covered_pixels'], 'pixel')} ({100 * info['covered_share']:.1f}% of the screen)")
    print(f"depth        max {dc['max']}, mean {dc['mean']:.2f} fragments per covered pixel")
    print("histogram    fragments/pixel  pixels")
    for label, pixels in bucket_histogram(dc["histogram"]):
        print(f"             {label:>15}  {pixels:,}")
    return 0
