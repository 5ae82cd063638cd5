"""``gpusim trace``: rasterize a scene (or import a CSV) into a trace file."""

from __future__ import annotations

import time
from pathlib import Path

from gpusim.cli.common import check_output, counted, parse_size
from gpusim.errors import GpusimError
from gpusim.scene import load_scene, trace_scene
from gpusim.trace_csv import read_csv_trace
from gpusim.trace_io import save_trace


def add_parser(sub) -> None:
    p = sub.add_parser("trace", help="rasterize a scene or import a CSV into a fragment trace (.npz)",
                       description="Rasterize SCENE (a scene TOML, a built-in scene name or a mesh file) "
                                   "or import --from-csv FILE into a fragment trace.")
    p.add_argument("scene", nargs="?", help="scene TOML file, built-in scene name, or OBJ/PLY/OFF/STL mesh")
    p.add_argument("-o", "--output", required=True, help="output trace file (.npz)")
    p.add_argument("--size", help="screen size WxH in pixels (overrides the scene's; required with --from-csv)")
    p.add_argument("--alpha", type=float, help="alpha of a mesh file given as SCENE (default 0.5)")
    p.add_argument("--from-csv", metavar="FILE", help="import fragments from a CSV file instead")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, e.g. --set camera.fov_y_deg=60 --set objects.0.alpha=0.3")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(run=run)


def run(args) -> int:
    out = Path(args.output)
    if out.suffix != ".npz":
        raise GpusimError(f"-o {out}: a trace file must end in .npz; e.g. -o traces/scene.npz")
    check_output(args.output)
    progress = False if args.no_progress else None
    start = time.perf_counter()
    if args.from_csv:
        if args.scene or args.set or args.alpha is not None:
            raise GpusimError("--from-csv takes no SCENE, --set or --alpha; give the CSV and --size only")
        if not args.size:
            raise GpusimError("--from-csv needs the screen size: add --size WIDTHxHEIGHT")
        width, height = parse_size(args.size)
        trace = read_csv_trace(args.from_csv, width, height)
    else:
        if not args.scene:
            raise GpusimError("name a SCENE (scene file, built-in name or mesh file) or use --from-csv")
        if Path(args.scene).suffix.lower() == ".csv":
            size = args.size or "WIDTHxHEIGHT"
            raise GpusimError(f"{args.scene}: a CSV fragment list is not a scene; import it with --from-csv: "
                              f"gpusim trace --from-csv {args.scene} --size {size} -o {args.output}")
        size = parse_size(args.size) if args.size else None
        scene, base = load_scene(args.scene, args.set, alpha=args.alpha, size=size)
        trace = trace_scene(scene, base, where=args.scene, progress=progress)
    save_trace(trace, out)
    dc = trace.depth_complexity()
    print(f"wrote {out}: {counted(len(trace), 'fragment')}, {counted(int((dc > 0).sum()), 'covered pixel')}, "
          f"max depth complexity {int(dc.max())} ({time.perf_counter() - start:.2f} s)")
    return 0
