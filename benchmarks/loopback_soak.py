"""Loopback soak: the skin board driver reading the pty emulator at 424 frame pairs/s for minutes.

Checks that acquisition keeps up indefinitely: every frame the emulator wrote is received (no
unexplained drops: a drop must show as a sequence gap counted in the stream's health), counts the
receive gaps longer than the 50 ms stall limit (on a shared machine, CPU starvation of this
process shows there first), and
reports the CPU share of the driver's receive thread (per-thread CPU clock) against the frame
period. As on `hardware=loopback`, the board scans in a process of its own
(`hardware.skin_board.board`) and the simulated world, with the emulator's bridge thread, runs in
this one. Baseline: the CPU the bench itself takes, which a real board does not put on the host:
the world and bridge threads here (per-thread clocks), the board process (its CPU time in /proc
over the same window). The board's side comes from its read-out (`SkinBoardEmulator.counts`:
frames written, twin frames held or skipped when the world fell behind); device-time gaps (board
time in each frame) beside the receive gaps tell a silent board from a host that did not read.

    python -m benchmarks.run loopback_soak          # 10 minutes (LSX_SOAK_S=600)
    LSX_SOAK_S=30 python -m benchmarks.run loopback_soak
"""

from __future__ import annotations

import gc
import os
import threading
import time


def _threads_cpu_s(*names: str) -> float:
    """CPU seconds of this process's threads of these names (per-thread clocks)."""
    return sum(time.clock_gettime(time.pthread_getcpuclockid(t.ident))
               for t in threading.enumerate() if t.name in names and t.ident is not None)


def _children_cpu_s() -> float:
    """CPU seconds of this process's running child processes (here: the board's), from /proc."""
    pids = set()
    for task in os.listdir("/proc/self/task"):
        with open(f"/proc/self/task/{task}/children") as f:
            pids.update(f.read().split())
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()  # after "pid (comm)"
        except FileNotFoundError:  # ended meanwhile
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime (clock ticks)
    return total / os.sysconf("SC_CLK_TCK")


def run() -> dict:
    import layerskin_exp.sim.config  # noqa: F401 - stores the sim, skin and world schemas
    from hardware.sim.realtime import RealtimeWorld
    from hardware.skin_board import SkinBoardConfig, SkinBoardEmulator, SkinBoardReader
    from layerskin_exp.config import compose

    seconds = float(os.environ.get("LSX_SOAK_S", "600"))
    world = compose("world")
    rt = RealtimeWorld.from_config(world.sim, world.skin, "platform")
    rt.start()
    emulator = SkinBoardEmulator(rt)
    path = emulator.start()
    reader = SkinBoardReader(SkinBoardConfig(port=path), world.skin)
    reader.connect()
    gc.freeze()  # as protocols.app does for real-time rigs: short full collections
    received, seq_errors, last_seq = 0, 0, None
    gaps = {"max_ms": 0.0, "over_50ms": 0, "last_host_ns": None, "device_max_ms": 0.0, "device_over_50ms": 0,
            "last_device_ns": None}

    def drain() -> None:
        nonlocal received, seq_errors, last_seq
        for f in reader.read_available():
            if last_seq is not None and f.seq != last_seq + 1:
                seq_errors += 1
            last_seq = f.seq
            received += 1
            if gaps["last_host_ns"] is not None:
                gap_ms = (f.host_t_ns - gaps["last_host_ns"]) / 1e6
                gaps["max_ms"] = max(gaps["max_ms"], gap_ms)
                gaps["over_50ms"] += gap_ms > 50
            gaps["last_host_ns"] = f.host_t_ns
            if gaps["last_device_ns"] is not None:  # board time: the device's own clock
                dev_ms = (f.device_t_ns - gaps["last_device_ns"]) / 1e6
                gaps["device_max_ms"] = max(gaps["device_max_ms"], dev_ms)
                gaps["device_over_50ms"] += dev_ms > 50
            gaps["last_device_ns"] = f.device_t_ns

    driver, bench = ("skin-board-rx",), ("realtime-world", "skin_board-emu-bridge", "skin_board-pipe-out")
    cpu0_bench, cpu0_drv, cpu0_children = _threads_cpu_s(*bench), _threads_cpu_s(*driver), _children_cpu_s()
    t0 = time.monotonic()
    try:
        while time.monotonic() - t0 < seconds:  # a stall is counted (receive gaps), not a reason to stop
            time.sleep(0.01)
            drain()
        wall = time.monotonic() - t0
        cpu_drv = _threads_cpu_s(*driver) - cpu0_drv
        cpu_bench = _threads_cpu_s(*bench) - cpu0_bench
        cpu_board = _children_cpu_s() - cpu0_children
        emulator.stall()  # the board stops scanning (in force on return); what it queued goes out and is read
        time.sleep(0.2)
        drain()
        board = dict(emulator.counts)  # its read-out (every 10 ms): no frame made since the stall
    finally:
        reader.disconnect()
        emulator.stop()
        rt.stop()
    # frames the board made; any still in its buffer (only if the pty filled) show as unexplained drops
    written = board.get("frames", 0)
    h = reader.health
    return {
        "soak_s": round(wall, 1),
        "max_receive_gap_ms": round(gaps["max_ms"], 1),
        "receive_gaps_over_50ms": gaps["over_50ms"],
        "max_device_time_gap_ms": round(gaps["device_max_ms"], 1),
        "device_time_gaps_over_50ms": gaps["device_over_50ms"],
        "world_worst_lag_ms": round(1e3 * rt.lag_s, 1),
        "frames_received": received,
        "frame_rate_hz": round(received / wall, 1),
        "frames_written_by_emulator": written,
        "board_rescans_world_behind (held)": board.get("held", 0),
        "board_twin_frames_skipped": board.get("skipped", 0),
        "lost_counted": h.lost,
        "corrupt_counted": h.corrupt,
        "ring_dropped": reader.ring_dropped,
        "unexplained_drops": int(written - received - h.lost - reader.ring_dropped),
        "sequence_breaks_seen": seq_errors,
        "driver_thread_cpu_share": round(cpu_drv / wall, 4),
        "baseline_bench_cpu_share (world + bridge, this process)": round(cpu_bench / wall, 4),
        "baseline_board_process_cpu_share": round(cpu_board / wall, 4),
        "driver_cpu_per_frame_us": round(1e6 * cpu_drv / max(received, 1), 1),
        "frame_period_us": 2360,
    }
