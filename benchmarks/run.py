"""Run benchmarks: python -m benchmarks.run NAME... [--json FILE] [--markdown FILE]   (NAME "all" runs every one).

A benchmark is a module benchmarks/<name>.py with `def run() -> dict` returning its figures and
a baseline measured in the same run.

--json writes {"machine": ..., "date": ..., "commit": ..., "results": {name: figures}}: the
figures with where and when they were measured (the guide's benchmark tables are generated from
such a file, docs/benchmarks/; see tools/doc_tables.py). --markdown writes the same as Markdown
tables, one per benchmark (`markdown(record)`, which the guide's generator calls too).
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import json
import os
import platform
import subprocess
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


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    """Where the figures were measured: CPU, cores this process may use, load, OS, Python, torch."""
    try:
        import torch

        torch_version = torch.__version__
    except ImportError:
        torch_version = None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu": _cpu_model(), "cores": cores, "load_1min": round(os.getloadavg()[0], 2),
            "os": f"{platform.system()} {platform.release()}", "python": platform.python_version(),
            "torch": torch_version}


def _commit() -> str | None:
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=HERE.parent, capture_output=True,
                             text=True, timeout=10)
    except OSError:
        return None
    return out.stdout.strip() or None


def _cell(value) -> str:
    if isinstance(value, float):
        value = f"{value:.4g}"
    elif isinstance(value, (list, tuple)):
        value = ", ".join(_cell(v) for v in value)
    elif isinstance(value, dict):
        value = "; ".join(f"{k} {_cell(v)}" for k, v in value.items())
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown(record: dict, names: list[str] | None = None) -> str:
    """The record's benchmarks (all, or `names`) as Markdown: a heading line per benchmark with its
    wall time, then a table of its figures."""
    parts = []
    for name in names or list(record["results"]):
        figures = dict(record["results"][name])
        wall = figures.pop("benchmark_wall_s", None)
        rows = [f"| `{key}` | {_cell(value)} |" for key, value in figures.items()]
        parts.append(f"`{name}` ({wall} s)\n\n| figure | value |\n|---|---|\n" + "\n".join(rows) + "\n")
    return "\n".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.run", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="+", help=f"benchmarks to run, or 'all' ({', '.join(available())})")
    parser.add_argument("--json", metavar="FILE", help="also write the results, the machine and the date as JSON")
    parser.add_argument("--markdown", metavar="FILE", help="also write the results as Markdown tables")
    args = parser.parse_args(argv)
    names = available() if "all" in args.names else args.names
    unknown = [n for n in names if n not in available()]
    if unknown:
        print(f"error: no benchmark {unknown}; available: {', '.join(available())}", file=sys.stderr)
        return 2
    record = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
              "machine": machine(), "commit": _commit(), "results": {}}
    for name in names:
        module = importlib.import_module(f"benchmarks.{name}")
        t0 = time.perf_counter()
        figures = module.run()
        figures["benchmark_wall_s"] = round(time.perf_counter() - t0, 1)
        record["results"][name] = figures
        print(f"== {name}")
        for key, value in figures.items():
            print(f"   {key:<28} {value}")
    record["machine"]["load_1min_after"] = round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None
    if args.json:
        Path(args.json).write_text(json.dumps(record, indent=2, default=str) + "\n")
    if args.markdown:
        Path(args.markdown).write_text(markdown(json.loads(json.dumps(record, default=str))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
