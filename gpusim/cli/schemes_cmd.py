"""``gpusim schemes``: the registered schemes and their parameters."""

from __future__ import annotations

from gpusim.cli.common import print_json
from gpusim.schemes import describe_scheme, scheme_class, scheme_names


def add_parser(sub) -> None:
    p = sub.add_parser("schemes", help="list the schemes and their parameters",
                       description="List every scheme, or one scheme's parameters with defaults and units.")
    p.add_argument("name", nargs="?", help="scheme to describe")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=run)


def run(args) -> int:
    names = [args.name] if args.name else scheme_names()
    table = {n: {"summary": scheme_class(n).summary, "params": describe_scheme(n)} for n in names}
    if args.json:
        print_json(table)
        return 0
    for name, info in table.items():
        print(f"{name}: {info['summary']}")
        for row in info["params"]:
            unit = f" [{row['unit']}]" if row["unit"] else ""
            print(f"    {row['name']} = {row['default']!r}{unit}  {row['type']}: {row['doc']}")
    return 0
