"""Where the test suite's time goes: the slowest tests, named, and the totals by file and by group,
from pytest's own `--durations=0` report.

    python -m benchmarks.suite_durations                       # runs `pytest -q --durations=0` (serial)
    python -m benchmarks.suite_durations -- -n 2 -m "not slow" # ... with these pytest arguments
    python -m benchmarks.suite_durations --from out.txt [--from more.txt]   # parses saved outputs
    python -m benchmarks.suite_durations --from out.txt --json results/suite-durations-DATE.json

A test's time is its setup, call and teardown added up. Its group is the folder under tests/ that
holds it (tests/sim, tests/hardware, ...; "tests" for the top-level files). Several outputs (say
`make test` and `make test-all`, each with `PYTEST_ARGS=--durations=0`) are read as one suite.
With xdist workers each test's time is its worker's wall clock, so per-test and per-group figures
add up to more than the run's wall time. This tool defines no `run()`: `make bench` (benchmarks.run
all) does not start the whole suite.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import re
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?)s\s+(setup|call|teardown)\s+(\S.*?)\s*$")
SUMMARY = re.compile(r"^=*\s*(\d+ (?:passed|failed).*?) in (\d+(?:\.\d+)?)s")
XDIST_GROUP = re.compile(r"@[\w.-]+$")  # --dist loadgroup appends "@group" to a grouped test's id
TOP = 30


def parse(text: str) -> tuple[dict[str, dict[str, float]], list[dict]]:
    """Per test id its phases' seconds, and each run's closing summary (counts and wall seconds)."""
    tests: dict[str, dict[str, float]] = defaultdict(dict)
    summaries = []
    for line in text.splitlines():
        m = DURATION.match(line)
        if m:
            seconds, phase, nodeid = float(m.group(1)), m.group(2), XDIST_GROUP.sub("", m.group(3))
            tests[nodeid][phase] = tests[nodeid].get(phase, 0.0) + seconds
            continue
        m = SUMMARY.match(line.strip())
        if m:
            summaries.append({"summary": m.group(1).strip(" ="), "wall_s": float(m.group(2))})
    return dict(tests), summaries


def group_of(nodeid: str) -> str:
    parts = nodeid.split("::", 1)[0].split("/")
    return "/".join(parts[:2]) if len(parts) > 2 else parts[0]


def profile(tests: dict[str, dict[str, float]], top: int = TOP) -> dict:
    """The `top` slowest tests and the totals per file and per group, slowest first."""
    total = {nodeid: sum(phases.values()) for nodeid, phases in tests.items()}
    by_file: dict[str, float] = defaultdict(float)
    by_group: dict[str, float] = defaultdict(float)
    count_file: dict[str, int] = defaultdict(int)
    count_group: dict[str, int] = defaultdict(int)
    for nodeid, seconds in total.items():
        path = nodeid.split("::", 1)[0]
        by_file[path] += seconds
        by_group[group_of(nodeid)] += seconds
        count_file[path] += 1
        count_group[group_of(nodeid)] += 1
    slowest = sorted(total.items(), key=lambda kv: -kv[1])[:top]
    return {
        "tests_timed": len(total),
        "total_s": round(sum(total.values()), 1),
        "slowest": [{"test": nodeid, "file": nodeid.split("::", 1)[0], "group": group_of(nodeid),
                     "s": round(seconds, 2),
                     "phases_s": {k: round(v, 2) for k, v in tests[nodeid].items()}}
                    for nodeid, seconds in slowest],
        "by_group": [{"group": g, "s": round(s, 1), "tests": count_group[g]}
                     for g, s in sorted(by_group.items(), key=lambda kv: -kv[1])],
        "by_file": [{"file": f, "s": round(s, 1), "tests": count_file[f]}
                    for f, s in sorted(by_file.items(), key=lambda kv: -kv[1])],
    }


def render(result: dict) -> str:
    """The profile as plain text: the slowest tests grouped under their file, then the totals."""
    out = [f"# Test-suite durations ({result.get('date', '')})", ""]
    for key in ("command", "note"):
        if result.get(key):
            out.append(f"{key}: {result[key]}")
    for run in result.get("runs", []):
        out.append(f"run: {run['summary']} in {run['wall_s']:.1f} s")
    out += [f"tests timed (pytest hides phases under 5 ms): {result['tests_timed']}, "
            f"their times added up: {result['total_s']:.1f} s", ""]
    out.append(f"## The {len(result['slowest'])} slowest tests (setup + call + teardown), by file")
    files: dict[str, list[dict]] = defaultdict(list)
    for t in result["slowest"]:
        files[t["file"]].append(t)
    for path, rows in sorted(files.items(), key=lambda kv: -sum(r["s"] for r in kv[1])):
        out.append(f"{path}  ({sum(r['s'] for r in rows):.1f} s of these)")
        for r in rows:
            out.append(f"  {r['s']:8.2f} s  {r['test'].split('::', 1)[1]}")
    out += ["", "## Totals by group"]
    out += [f"  {g['s']:8.1f} s  {g['tests']:5d} tests  {g['group']}" for g in result["by_group"]]
    out += ["", "## Totals by file"]
    out += [f"  {f['s']:8.1f} s  {f['tests']:5d} tests  {f['file']}" for f in result["by_file"]]
    return "\n".join(out) + "\n"


def run_pytest(pytest_args: list[str], log: Path) -> str:
    cmd = [sys.executable, "-m", "pytest", "-q", "--durations=0", *pytest_args]
    t0 = time.perf_counter()
    with log.open("w") as fh:
        proc = subprocess.run(cmd, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT, check=False)
    print(f"pytest exited {proc.returncode} after {time.perf_counter() - t0:.0f} s; output in {log}",
          file=sys.stderr)
    return log.read_text()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.suite_durations", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--from", dest="sources", type=Path, action="append", default=[],
                        help="a saved pytest --durations=0 output (repeatable); without it pytest runs")
    parser.add_argument("--log", type=Path, default=Path("suite-durations.log"),
                        help="where pytest's output goes when this tool runs it")
    parser.add_argument("--json", type=Path, help="also write the profile as JSON")
    parser.add_argument("--txt", type=Path, help="write the text report here instead of stdout")
    parser.add_argument("--top", type=int, default=TOP)
    parser.add_argument("--note", default="", help="a line kept with the figures (machine, load)")
    parser.add_argument("pytest_args", nargs="*", help="after --: arguments for pytest")
    args = parser.parse_args(argv)
    if args.sources:
        texts = [p.read_text() for p in args.sources]
        command = "parsed from " + ", ".join(p.name for p in args.sources)
    else:
        texts = [run_pytest(args.pytest_args, args.log)]
        command = " ".join(["pytest -q --durations=0", *args.pytest_args])
    tests: dict[str, dict[str, float]] = {}
    runs: list[dict] = []
    for text in texts:
        parsed, summaries = parse(text)
        for nodeid, phases in parsed.items():
            tests.setdefault(nodeid, {}).update(phases)
        runs += summaries
    if not tests:
        print("error: no durations found (run pytest with --durations=0)", file=sys.stderr)
        return 2
    result = {"date": _dt.date.today().isoformat(), "command": command, "note": args.note, "runs": runs,
              **profile(tests, args.top)}
    text = render(result)
    if args.txt:
        args.txt.parent.mkdir(parents=True, exist_ok=True)
        args.txt.write_text(text)
    else:
        sys.stdout.write(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
