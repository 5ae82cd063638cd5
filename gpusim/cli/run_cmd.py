"""``gpusim run``: run an experiment (a sweep over scenes, GPUs, levels and scheme parameters) and report it."""

from __future__ import annotations

import sys
from pathlib import Path

from gpusim.errors import GpusimError
from gpusim.experiment import DEFAULT_EXPERIMENT, describe_summary, load_experiment, run_experiment
from gpusim.experiment.runner import check_workers


def add_parser(sub) -> None:
    p = sub.add_parser("run", help="run an experiment file: results tables and a report",
                       description="Run every grid point of an experiment (configs/experiments/*.toml) into DIR "
                                   "(default reports/<name>/): results.parquet/.csv, stats.parquet, resolved.toml, "
                                   "runs/<run>/, then the report (index.md, figures/). Finished runs found in DIR "
                                   "are reused, so an interrupted sweep resumes.")
    p.add_argument("file", nargs="?", metavar="FILE",
                   help=f"experiment file, or a bundled experiment's name (default: {DEFAULT_EXPERIMENT})")
    p.add_argument("-o", "--output", metavar="DIR", help="output directory (default reports/<name>/)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override an experiment key, e.g. --set fidelity='[\"full\"]' --set schemes.kbuffer.k=[4]")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes, 1 up to the CPUs available (the default: one per CPU; "
                        "1 runs in this process); --cluster for more")
    p.add_argument("--cluster", metavar="ADDRESS", help="run on a dask.distributed scheduler, e.g. tcp://host:8786")
    p.add_argument("--no-report", action="store_true", help="write the tables only; no index.md or figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar or progress lines; errors still print")
    p.set_defaults(run=run)


def run(args) -> int:
    if args.workers is not None and args.cluster:
        raise GpusimError("--workers and --cluster exclude each other: the cluster's workers run the tasks")
    check_workers(args.workers)               # 1..the CPUs here: before anything is read or written
    exp = load_experiment(args.file, args.set)
    out = Path(args.output or Path("reports") / exp.name)
    try:                                      # SIGTERM arrives as KeyboardInterrupt (gpusim.cli.main)
        summary = run_experiment(exp, out, args.workers, args.cluster, args.quiet)
        if not args.no_report:
            from gpusim.report.experiment import write_report
            index = write_report(out)
            if not args.quiet:
                print(f"report: {index}", file=sys.stderr)
    except KeyboardInterrupt:
        kept = (f"finished runs are kept in {out}: run the same command again to resume"
                if (out / "runs").is_dir() else "nothing was written")
        print(f"gpusim: interrupted; {kept}", file=sys.stderr)
        return 130
    lines = describe_summary(summary)
    for line in lines[:-1]:
        print(line, file=sys.stderr if args.quiet else sys.stdout)
    print(lines[-1])
    return 1 if summary.failed else 0
