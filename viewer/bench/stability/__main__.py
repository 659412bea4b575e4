"""Run the stability studies, print their tables and write docs/STABILITY.md.

    python -m viewer.bench.stability [--quick] [--only NAME ...] [--methods NAME ...] [--no-write]

Charts go to docs/images/stability, CSV to docs/data/stability; Mitsuba results are cached on disk.
"""

from __future__ import annotations

import importlib
import time

from viewer.bench.stability import report
from viewer.bench.stability.common import RunConfig, format_table
from viewer.bench.stability.methods import METHODS, method_names
from viewer.sources import ALIASES

STUDIES = tuple(report.TITLES)


def main(argv=None) -> int:
    from viewer.cli_parsing import tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.bench.stability")
    parser.add_argument("--quick", action="store_true", help="fewer scenes, steps and resolutions (minutes)")
    parser.add_argument("--only", nargs="+", choices=STUDIES, metavar="NAME", help=f"only these: {', '.join(STUDIES)}")
    parser.add_argument("--methods", nargs="+", choices=(*METHODS, *ALIASES), metavar="NAME",
                        help=f"only these methods: {', '.join(METHODS)}")
    parser.add_argument("--no-write", dest="write", action="store_false", help="print only; leave docs/ alone")
    parser.add_argument("--charts-only", dest="charts_only", action="store_true",
                        help="redraw the charts and blocks from the saved results (docs/data/stability/*.json)")
    args = parser.parse_args(argv)
    config = RunConfig(quick=args.quick, methods=tuple(method_names(args.methods or METHODS)))
    if args.write:
        report.write_methods(METHODS)
    for name in args.only or STUDIES:
        module = importlib.import_module(f"viewer.bench.stability.{name}")
        start = time.perf_counter()
        result = report.load(name) if args.charts_only else module.run(config)
        if result is None:
            print(f"{name}: no saved results to redraw")
            continue
        print(f"\n## {report.TITLES[name]} ({time.perf_counter() - start:.0f} s)\n")
        if result.rows:
            print(format_table(result))
        for line in result.notes + result.summary:
            print(f"- {line}")
        if args.write:
            report.write(result, module.chart)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
