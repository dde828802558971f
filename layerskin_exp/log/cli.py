"""Command line: inspect a session file, recover one whose writer died, print a Foxglove layout,
export a folder of sessions as a LeRobot dataset, open sessions in the rerun viewer."""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from datetime import datetime, timezone
from typing import TYPE_CHECKING

import numpy as np

from layerskin_exp.log.errors import SessionFileError

if TYPE_CHECKING:
    from layerskin_exp.log.session.reader import Session


def describe(s: Session) -> str:
    """Human-readable summary: outcome, labels, the drivers' stream-health counters, and per stream
    count, rate, duration, gaps."""
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
    if s.damaged_fields:
        lines.append(f"  DAMAGED METADATA (left out): {', '.join(s.damaged_fields)}")
    if s.unchecked:
        lines.append(f"  metadata unchecked (written without checks): {', '.join(s.unchecked)}")
    if s.repeats:
        lines.append(f"  repeats dropped: {s.repeats} (exact copies of messages read once)")
    if "recovered" in s.metadata:
        lines.append(f"  recovered: {s.metadata['recovered']}")
    lines.append(f"  labels: {s.labels}")
    lines.append(f"  backend: {s.metadata.get('backend')}   version: {s.metadata.get('version')}")
    lines += _health(s.stream_health)
    starts = [a["t_ns"][0] for a in s.streams.values() if len(a["t_ns"])]
    ends = [a["t_ns"][-1] for a in s.streams.values() if len(a["t_ns"])]
    if starts:
        began = datetime.fromtimestamp(int(s.unix_ns(min(starts))) / 1e9, timezone.utc)
        lines.append(f"  started: {began:%Y-%m-%d %H:%M:%S.%f} UTC (log times: host + {s.epoch_offset_ns} ns)")
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


HEALTH_COUNTERS = ("received", "lost", "dropped", "duplicate", "out_of_order", "corrupt", "reconnects")


def _health(health: dict | None) -> list[str]:
    """The drivers' stream-health counters over the trial, one row per device."""
    if health is None:
        return ["  stream health: not recorded (a file written before the drivers' counters were stored, "
                "or not closed by its writer)"]
    if not health:
        return ["  stream health: no device counters"]
    lines = ["  stream health (the drivers' counters over the trial; lost = sequence gaps, dropped = "
             "overflowed the driver's buffer):",
             "    " + f"{'device':<12}" + "".join(f"{c.replace('_', ' '):>13}" for c in HEALTH_COUNTERS)]
    for device, counters in sorted(health.items()):
        lines.append("    " + f"{device:<12}" + "".join(
            f"{counters[c] if c in counters else '-':>13}" for c in HEALTH_COUNTERS))
    return lines


EXIT_COMPLETE = 0
EXIT_INCOMPLETE = 1  # readable, but damaged, cut off (no outcome), incomplete or aborted
EXIT_UNREADABLE = 2


def _layout(target: str, estimate: bool, camera: bool) -> str:
    """The app-format layout of a rig (target "platform"/"gripper") or stored in a session file."""
    from layerskin_exp.log.session import schema as S
    from layerskin_exp.log.view.layout import SETUPS, rig_layout

    if target in SETUPS:
        return json.dumps(rig_layout(target, estimate=estimate, camera=camera), indent=1)
    from layerskin_exp.log.container.scan import scan

    stored = dict(scan(target).metadata).get(S.META_LAYOUT_APP)
    if not stored:
        raise SessionFileError(f"{target}: no stored layout (the writer did not close this file); "
                               f"print a rig's instead: layout {'|'.join(SETUPS)}")
    return json.dumps(json.loads(stored[""]), indent=1)


def _emit(text: str) -> None:
    """Print; a reader that stops early (`| head`) ends the output quietly, not with a traceback."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        # Python would report the pipe again when it flushes stdout at exit: point it at devnull.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def _export(args) -> int:
    """export lerobot: the report on stdout; bad input one line on stderr, exit 2."""
    from layerskin_exp.log.export.lerobot import ExportError, export_lerobot

    try:
        report = export_lerobot(args.sessions, args.out, fps=args.fps)
    except (ExportError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_UNREADABLE
    _emit(report.describe())
    return 0


def _view(args) -> int:
    """view: the rerun viewer (native, --web, or --save); bad input or rerun missing: one line, exit 2."""
    from layerskin_exp.log.view.rerun_view import ViewerError, save, view

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # `inspect` lists damage; the viewer shows what was read
            if args.save:
                for path in save(args.sessions, args.save):
                    _emit(f"wrote {path}")
            else:
                view(args.sessions, web=args.web, port=args.port, grpc_port=args.grpc_port, bind=args.bind)
    except (ViewerError, SessionFileError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_UNREADABLE
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m layerskin_exp.log", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p_inspect = sub.add_parser(
        "inspect", help="print streams, rates, gaps, duration, outcome, labels, the drivers' stream-health "
        "counters; exit 0 for a complete trial, 1 for a readable one that is damaged, cut off, incomplete or "
        "aborted, 2 for an unreadable file")
    p_inspect.add_argument("file")
    p_recover = sub.add_parser("recover", help="rewrite a file whose writer died into a valid MCAP")
    p_recover.add_argument("input")
    p_recover.add_argument("output")
    p_layout = sub.add_parser("layout", help="print a Foxglove layout (JSON for the app's Layouts > Import): "
                              "a rig's, for the live view, or the one a session file stores")
    p_layout.add_argument("target", help="platform | gripper | a session file")
    p_layout.add_argument("--estimate", action="store_true", help="with the live estimator's panels")
    p_layout.add_argument("--camera", action="store_true", help="with the camera image (gripper rig)")
    p_export = sub.add_parser("export", help="write a folder of sessions in another format")
    export_sub = p_export.add_subparsers(dest="format", required=True)
    p_lerobot = export_sub.add_parser(
        "lerobot", help="one LeRobot v3.0 dataset, one episode per complete trial (docs/export.md); damaged, "
        "cut-off, incomplete or aborted trials are left out and listed")
    p_lerobot.add_argument("sessions", help="a folder of session files (searched recursively), or one .mcap")
    p_lerobot.add_argument("out", help="the dataset's folder: new, or empty")
    p_lerobot.add_argument("--fps", type=int, default=None,
                           help="the dataset's frame rate (default: the skin's frame rate / 5, the study's "
                           "downsampling, rounded: 85 for the study's skin)")
    p_view = sub.add_parser(
        "view", help="open sessions in the rerun viewer (docs/viewer.md; needs the 'view' extra: "
        "pip install 'layerskin-exp[view]'), with the panels of the stored Foxglove layout")
    p_view.add_argument("sessions", nargs="+", help="session files (.mcap) or folders of them")
    p_view.add_argument("--web", action="store_true", help="serve the web viewer on http://127.0.0.1:PORT "
                        "instead of opening the native one")
    p_view.add_argument("--port", type=int, default=9090, help="the web viewer's HTTP port (default 9090)")
    p_view.add_argument("--grpc-port", type=int, default=9876, help="the port the web viewer reads the "
                        "recordings from (default 9876)")
    p_view.add_argument("--bind", default="127.0.0.1", help="with --web: the address to listen on (default "
                        "127.0.0.1, this machine only; 0.0.0.0 lets any host that reaches this one read the sessions)")
    p_view.add_argument("--save", metavar="OUT", help="write the recordings to OUT.rrd (a folder for several "
                        "sessions) instead of opening a viewer")
    args = parser.parse_args(argv)
    if args.command == "export":
        return _export(args)
    if args.command == "view":
        return _view(args)
    # the reader (scipy, OpenCV, the schemas) loads for a file to read, not for --help
    from layerskin_exp.log.container.recover import recover
    from layerskin_exp.log.session.reader import load_session

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # damage is listed in the report itself
            if args.command == "layout":
                _emit(_layout(args.target, args.estimate, args.camera))
                return 0
            if args.command == "inspect":
                s = load_session(args.file, warn=False)
                _emit(describe(s))
                return EXIT_COMPLETE if s.complete else EXIT_INCOMPLETE
            n = recover(args.input, args.output)
            _emit(f"recovered {n} messages from {args.input} into {args.output} (marked incomplete)")
    except (SessionFileError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_UNREADABLE
    return 0
