"""``gpusim config``: the resolved experiment and its runs, without running anything."""

from __future__ import annotations

from gpusim.cli.common import counted
from gpusim.experiment import expand, load_experiment


def add_parser(sub) -> None:
    p = sub.add_parser("config", help="print an experiment's resolved runs (nothing runs)",
                       description="Load an experiment (includes and --set applied), validate it and print its "
                                   "runs as a table with their count; --toml prints the resolved file instead.")
    p.add_argument("file", nargs="?", metavar="FILE", help="experiment file or bundled name (default quick-start)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override an experiment key")
    p.add_argument("--toml", action="store_true", help="print the resolved experiment as TOML")
    p.set_defaults(run=run)


def run(args) -> int:
    exp = load_experiment(args.file, args.set)
    if args.toml:
        from gpusim.experiment.store import toml_text
        print(toml_text(exp.resolved_data(), f"# {exp.path}, resolved\n"), end="")
        return 0
    runs = expand(exp)
    given = {e.label: list(e.axes) for e in exp.schemes}
    sets = list(exp.gpu_set)
    scene_sets = list(dict.fromkeys(k for r in runs for k, _ in r.source.scene_set))
    head = ["#", "scene", *[f"scene.{k}" for k in scene_sets], "gpu", *sets, "fidelity", "scheme", "parameters",
            "note"]
    rows = []
    for r in runs:
        params = " ".join(f"{k}={r.params[k]}" for k in given[r.label]) or "defaults"
        scheme = r.scheme if r.label == r.scheme else f"{r.label} ({r.scheme})"
        scene = dict(r.source.scene_set)
        rows.append([str(r.index), r.source.label, *[str(scene.get(k, "")) for k in scene_sets], r.gpu,
                     *[str(v) for _, v in r.gpu_set], r.fidelity, scheme, params,
                     f"skipped: {r.skip}" if r.skip else ""])
    widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(head)]
    print(f"{exp.name}: {exp.description}" if exp.description else exp.name)
    for row in [head, *rows]:
        print("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
    skipped = sum(1 for r in runs if r.skip)
    print(counted(len(runs), "run") + (f" ({skipped} skipped)" if skipped else ""))
    return 0
