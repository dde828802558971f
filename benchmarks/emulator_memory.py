"""Standalone emulators' memory over time: `python -m hardware.emulate DEVICE` left running, with
no client (what a developer does between two test runs), its resident set size (VmRSS) read
every few seconds.

A standalone emulator runs the whole simulated setup of its device but serves one stream; the
others must not pile up. The figure is the growth in MB/min over the run after the first
minute (start-up allocations settle then), beside the RSS at that minute (the baseline, same run).

    python -m benchmarks.emulator_memory                        # every device, 10 min, in parallel
    python -m benchmarks.emulator_memory --minutes 3 platform skin_board
    python -m benchmarks.emulator_memory --repo /tmp/old-checkout platform   # another checkout's code
    LSX_EMU_MEM_MIN=3 LSX_EMU_MEM_DEVICES=platform,skin_board python -m benchmarks.run emulator_memory
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEVICES = ("skin_board", "platform", "netft", "ur5e", "hande", "camera")
SETTLE_S = 60.0  # start-up allocations (kernels, first frames) are left out of the growth


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for pid {pid}")


def _free_host() -> str:
    from hardware.emulation import free_loopback_host

    return free_loopback_host({49152: socket.SOCK_DGRAM, 80: socket.SOCK_STREAM, 63352: socket.SOCK_STREAM,
                               **{p: socket.SOCK_STREAM for p in (29999, 30001, 30002, 30003, 30004)}})


def _launch(device: str, repo: Path) -> subprocess.Popen:
    args = [sys.executable, "-m", "hardware.emulate", device]
    if device in ("netft", "hande", "ur5e"):
        args += ["--host", _free_host()]
    proc = subprocess.Popen(args, cwd=repo, env={**os.environ, "PYTHONPATH": str(repo)}, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    line = proc.stdout.readline()
    if "listening on" not in line:
        proc.kill()
        raise RuntimeError(f"{device} emulator did not start: {line!r}")
    return proc


def measure(devices, minutes: float, sample_s: float = 5.0, repo: Path = REPO) -> dict:
    """device -> {rss_mb: [(t_s, MB), ...], baseline_mb, end_mb, growth_mb_per_min}; the emulators
    run side by side."""
    procs = {}
    try:
        for d in devices:
            procs[d] = _launch(d, repo)
            time.sleep(1.0)  # (each binds its own loopback address)
        t0 = time.monotonic()
        series = {d: [] for d in devices}
        while True:
            t = time.monotonic() - t0
            for d, p in procs.items():
                if p.poll() is not None:
                    raise RuntimeError(f"{d} emulator exited with {p.returncode}")
                series[d].append((round(t, 1), round(_rss_mb(p.pid), 1)))
            if t >= minutes * 60.0:
                break
            time.sleep(sample_s)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in procs.values():
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
    out = {}
    for d, pts in series.items():
        t, mb = np.array(pts).T
        late = t >= min(SETTLE_S, t[-1] / 2)
        slope = float(np.polyfit(t[late], mb[late], 1)[0]) * 60.0 if late.sum() >= 2 else float("nan")
        out[d] = {"baseline_mb": float(mb[late][0]), "end_mb": float(mb[-1]), "growth_mb_per_min": round(slope, 2),
                  "rss_mb": pts}
    return out


def run() -> dict:
    minutes = float(os.environ.get("LSX_EMU_MEM_MIN", "10"))
    devices = os.environ.get("LSX_EMU_MEM_DEVICES", ",".join(DEVICES)).split(",")
    res = measure(devices, minutes)
    figures = {"minutes": minutes}
    for d, r in res.items():
        figures[f"{d}_growth_mb_per_min"] = r["growth_mb_per_min"]
        figures[f"{d}_rss_mb_at_1min_baseline"] = r["baseline_mb"]
        figures[f"{d}_rss_mb_end"] = r["end_mb"]
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.emulator_memory", description=__doc__.split("\n\n")[0])
    parser.add_argument("devices", nargs="*", help=f"some of {', '.join(DEVICES)} (default: all)")
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--sample-s", type=float, default=5.0)
    parser.add_argument("--repo", type=Path, default=REPO, help="checkout whose emulators to run (default: this one)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.devices) - set(DEVICES))
    if unknown:
        parser.error(f"devices {unknown}: choose among {', '.join(DEVICES)}")
    res = measure(args.devices or DEVICES, args.minutes, args.sample_s, args.repo)
    for d, r in res.items():
        every = max(1, len(r["rss_mb"]) // 12)
        trace = ", ".join(f"{t:.0f}s {mb:.0f}" for t, mb in r["rss_mb"][::every])
        print(f"{d:<11} RSS {r['baseline_mb']:.0f} MB at the first minute -> {r['end_mb']:.0f} MB; "
              f"growth {r['growth_mb_per_min']:+.2f} MB/min   [{trace}]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
