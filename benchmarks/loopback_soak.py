"""Loopback soak: the skin board driver reading the pty emulator at 424 frame pairs/s for minutes.

Checks that acquisition keeps up indefinitely: every frame the emulator wrote is received (no
unexplained drops: a drop must show as a sequence gap counted in the stream's health), counts the
receive gaps longer than the 50 ms stall limit (on a shared machine, CPU starvation of this
process shows there first), and
reports the CPU share of the driver's receive thread (per-thread CPU clock) against the frame
period, with the emulator and the simulated world running in the same process as on
`hardware=loopback`. Baseline: the same figures for the emulator + world alone (the load the
bench adds, which a real board does not put on the host).

    python -m benchmarks.run loopback_soak          # 10 minutes (LSX_SOAK_S=600)
    LSX_SOAK_S=30 python -m benchmarks.run loopback_soak
"""

from __future__ import annotations

import gc
import os
import time


def _thread_cpu_s(thread) -> float:
    return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))


def run() -> dict:
    import layerskin_exp.sim.config  # noqa: F401 - stores the sim, skin and world schemas
    from hardware.sim.realtime import RealtimeWorld
    from hardware.skin_board import SkinBoardConfig, SkinBoardEmulator, SkinBoardReader
    from hardware.skin_board.wire import FRAME_LEN
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
    received, seq_errors, last_seq, in_flight = 0, 0, None, 0
    gaps = {"max_ms": 0.0, "over_50ms": 0, "last_host_ns": None}

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

    cpu0_world, cpu0_emu = _thread_cpu_s(rt._thread), _thread_cpu_s(emulator._thread)
    cpu0_drv, t0 = _thread_cpu_s(reader._thread), time.monotonic()
    try:
        while time.monotonic() - t0 < seconds:  # a stall is counted (receive gaps), not a reason to stop
            time.sleep(0.01)
            drain()
        wall = time.monotonic() - t0
        cpu_drv = _thread_cpu_s(reader._thread) - cpu0_drv
        cpu_bench = (_thread_cpu_s(rt._thread) - cpu0_world) + (_thread_cpu_s(emulator._thread) - cpu0_emu)
        emulator.stall()  # the board stops scanning; what it already queued goes out and is read
        time.sleep(0.2)
        drain()
        emulator.stop()
        in_flight = -(-len(emulator._pending) // FRAME_LEN)  # queued but never sent (0 unless the pty filled)
    finally:
        reader.disconnect()
        emulator.stop()
        rt.stop()
    written = emulator.counts["frames"] - in_flight
    h = reader.health
    return {
        "soak_s": round(wall, 1),
        "max_receive_gap_ms": round(gaps["max_ms"], 1),
        "receive_gaps_over_50ms": gaps["over_50ms"],
        "world_worst_lag_ms": round(1e3 * rt.lag_s, 1),
        "frames_received": received,
        "frame_rate_hz": round(received / wall, 1),
        "frames_written_by_emulator": written,
        "lost_counted": h.lost,
        "corrupt_counted": h.corrupt,
        "ring_dropped": reader.ring_dropped,
        "unexplained_drops": int(written - received - h.lost - reader.ring_dropped),
        "sequence_breaks_seen": seq_errors,
        "driver_thread_cpu_share": round(cpu_drv / wall, 4),
        "baseline_bench_cpu_share (world + emulator)": round(cpu_bench / wall, 4),
        "driver_cpu_per_frame_us": round(1e6 * cpu_drv / max(received, 1), 1),
        "frame_period_us": 2360,
    }
