"""``gpusim show``: PNGs of the exact reference image and the depth-complexity map."""

from __future__ import annotations

from pathlib import Path

from gpusim.atomic_io import atomic_folder
from gpusim.cli.common import check_output
from gpusim.metrics import composite_exact
from gpusim.trace_io import load_trace


def add_parser(sub) -> None:
    p = sub.add_parser("show", help="write PNGs of the reference image and depth complexity",
                       description="Write DIR/reference.png (exact OIT composite) and "
                                   "DIR/depth_complexity.png (fragments per pixel).")
    p.add_argument("trace", help="trace file (.npz)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.set_defaults(run=run)


def run(args) -> int:
    from gpusim.report.images import save_heatmap_png, save_image_png

    out = check_output(args.output, folder=True)
    trace = load_trace(args.trace)
    dc = trace.depth_complexity()
    with atomic_folder(out) as tmp:                # both images appear together, or neither
        save_image_png(composite_exact(trace), tmp / "reference.png")
        save_heatmap_png(dc, tmp / "depth_complexity.png",
                         title=f"depth complexity ({trace.meta.get('scene', Path(args.trace).stem)}, "
                               f"max {int(dc.max())})", label="fragments per pixel", log=dc.max() > 64)
    print(f"wrote {out / 'reference.png'} and {out / 'depth_complexity.png'}")
    return 0
