"""Command line: inspect a session file, recover one whose writer died, print the Foxglove layout."""

from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np

from layerskin_exp.log.session.reader import Session, load_session
from layerskin_exp.log.container.recover import recover
from layerskin_exp.log.container.scan import SessionFileError


def describe(s: Session) -> str:
    """Human-readable summary: outcome, labels, and per stream count, rate, duration, gaps."""
    lines = [
        f"{s.path}",
        f"  outcome: {s.outcome or 'none (writer did not close the file)'}   complete: {s.complete}",
    ]
    if s.damaged:
        known = [x for x in s.lost if x.messages is not None]
        n_lost = sum(sum(x.messages.values()) for x in known)
        more = " (and an unknown number more)" if len(known) < len(s.lost) else ""
        lines.append(
            f"  DAMAGED: {s.chunks_skipped} chunk(s) skipped, {n_lost} message(s) lost{more} in "
            f"{len(s.lost)} range(s); everything else was read. `recover` rewrites the file around it."
        )
        firsts = [a["host_t_ns"][0] for a in s.streams.values() if len(a["host_t_ns"])]
        for x in s.lost:
            at = ""
            if firsts and x.start_ns is not None and x.end_ns is not None:
                t0 = int(min(firsts))
                at = f" [{(x.start_ns - t0) / 1e9:.3f} .. {(x.end_ns - t0) / 1e9:.3f} s into the session]"
            lines.append(f"  lost: {x.describe()}{at}")
    if "recovered" in s.metadata:
        lines.append(f"  recovered: {s.metadata['recovered']}")
    lines.append(f"  labels: {s.labels}")
    lines.append(f"  backend: {s.metadata.get('backend')}   version: {s.metadata.get('version')}")
    starts = [a["t_ns"][0] for a in s.streams.values() if len(a["t_ns"])]
    ends = [a["t_ns"][-1] for a in s.streams.values() if len(a["t_ns"])]
    if starts:
        lines.append(f"  duration: {(max(ends) - min(starts)) / 1e9:.3f} s")
    lines.append(
        f"  {'stream':<14}{'count':>9}{'rate Hz':>10}{'dur s':>9}{'seq gaps':>10}{'lost':>7}"
        f"{'time gaps':>11}{'max gap ms':>12}"
    )
    for name, a in sorted(s.streams.items()):
        t = a["t_ns"]
        n = len(t)
        dur = (t[-1] - t[0]) / 1e9 if n > 1 else 0.0
        rate = (n - 1) / dur if dur > 0 else float("nan")
        seq_gaps = lost = 0
        if "seq" in a and n > 1:
            d = np.diff(a["seq"])
            seq_gaps, lost = int(np.sum(d > 1)), int(np.sum(d[d > 1] - 1))
        time_gaps, max_gap = 0, 0.0
        if n > 2:
            dt = np.diff(np.sort(t))
            med = float(np.median(dt))
            time_gaps = int(np.sum(dt > 2 * med)) if med > 0 else 0
            max_gap = float(dt.max()) / 1e6
        lines.append(
            f"  {name:<14}{n:>9}{rate:>10.1f}{dur:>9.2f}{seq_gaps:>10}{lost:>7}{time_gaps:>11}"
            f"{max_gap:>12.2f}"
        )
    for w in s.warnings:
        lines.append(f"  warning: {w}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m layerskin_exp.log", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p_inspect = sub.add_parser("inspect", help="print streams, rates, gaps, duration, outcome, labels")
    p_inspect.add_argument("file")
    p_recover = sub.add_parser("recover", help="rewrite a file whose writer died into a valid MCAP")
    p_recover.add_argument("input")
    p_recover.add_argument("output")
    sub.add_parser("layout", help="print the Foxglove layout every session carries (JSON, for Layouts > Import)")
    args = parser.parse_args(argv)
    if args.command == "layout":
        from layerskin_exp.log.view.layout import session_layout

        print(session_layout().to_json())
        return 0
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # damage is listed in the report itself
            if args.command == "inspect":
                print(describe(load_session(args.file, warn=False)))
            else:
                n = recover(args.input, args.output)
                print(f"recovered {n} messages from {args.input} into {args.output} (marked incomplete)")
    except (SessionFileError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
