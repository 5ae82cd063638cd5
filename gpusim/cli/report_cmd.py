"""``gpusim report``: index.md and figures from an experiment's results tables."""

from __future__ import annotations

from pathlib import Path

from gpusim.errors import GpusimError


def add_parser(sub) -> None:
    p = sub.add_parser("report", help="write index.md and figures from an experiment directory's tables",
                       description="Read DIR/results.parquet and DIR/stats.parquet (written by gpusim run) and "
                                   "write OUT/index.md and OUT/figures/*.png (OUT defaults to DIR).")
    p.add_argument("dir", metavar="DIR", help="an experiment output directory")
    p.add_argument("-o", "--output", metavar="OUT", help="report directory (default DIR)")
    p.set_defaults(run=run)


def run(args) -> int:
    if not (Path(args.dir) / "results.parquet").is_file():
        raise GpusimError(f"{args.dir}: no results.parquet here; run an experiment into it first "
                          f"(gpusim run FILE -o {args.dir})")
    from gpusim.report.experiment import write_report
    print(f"wrote {write_report(Path(args.dir), Path(args.output) if args.output else None)}")
    return 0
