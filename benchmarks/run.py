"""Run benchmarks: python -m benchmarks.run NAME... [--json FILE]   (NAME "all" runs every one).

A benchmark is a module benchmarks/<name>.py with `def run() -> dict` returning its figures and
a baseline measured in the same run.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).parent


def available() -> list[str]:
    """Names of modules in benchmarks/ that define run()."""
    names = []
    for path in sorted(HERE.glob("*.py")):
        if path.stem in ("__init__", "run", "__main__") or path.stem.startswith("_"):
            continue
        if "def run(" in path.read_text():
            names.append(path.stem)
    return names


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.run", description=__doc__)
    parser.add_argument("names", nargs="+", help=f"benchmarks to run, or 'all' ({', '.join(available())})")
    parser.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    args = parser.parse_args(argv)
    names = available() if "all" in args.names else args.names
    unknown = [n for n in names if n not in available()]
    if unknown:
        print(f"error: no benchmark {unknown}; available: {', '.join(available())}", file=sys.stderr)
        return 2
    results = {}
    for name in names:
        module = importlib.import_module(f"benchmarks.{name}")
        t0 = time.perf_counter()
        figures = module.run()
        figures["benchmark_wall_s"] = round(time.perf_counter() - t0, 1)
        results[name] = figures
        print(f"== {name}")
        for key, value in figures.items():
            print(f"   {key:<28} {value}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
