"""`hardware=loopback` end to end: both protocols through the real drivers (pyserial on ptys,
Net F/T over UDP, the installed ur_rtde client, the URCap socket, OpenCV capture) against the
emulators, backed by the simulated world at wall-clock pace. The session files pass the same
checks as simulated ones; a stalled stream stops the trial safely; kill -9 keeps the file."""

from __future__ import annotations

import os
import re
import signal
import time

import numpy as np
import pytest

from hardware.hande.config import HandEConfig
from layerskin_exp.log import load_session
from protocols.calibration import plan_trials
from tests.protocols.conftest import TINY_GRIP, compose_app, design_dir, popen_cli, run_cli
from tests.protocols.test_apps import check_calibration_session, check_grip_session

LOOPBACK_CAL = ["hardware=loopback", "positions.count=1", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05",
                "progress=false"]


def test_calibration_on_loopback(tmp_path, hydra_dirs):
    data = tmp_path / "data"
    r = run_cli("protocols.force_calibration", [*LOOPBACK_CAL, f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    _, typed = compose_app("force_calibration", LOOPBACK_CAL)
    folder = design_dir(data / "force_calibration")
    for trial in plan_trials(typed):
        s = load_session(folder / f"{trial.name}.mcap", warn=False)
        assert s.metadata["backend"] == "loopback"
        check_calibration_session(s, trial, typed, rate_tol=0.1)


def test_grip_on_loopback_with_the_ur_rtde_client(tmp_path, hydra_dirs):
    data = tmp_path / "data"
    args = ["hardware=loopback", *TINY_GRIP, "progress=false"]
    r = run_cli("protocols.grip_depth", [*args, f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    _, typed = compose_app("grip_depth", args)
    (f,) = design_dir(data / "grip_depth").glob("*.mcap")
    s = load_session(f, warn=False)
    assert s.metadata["backend"] == "loopback"
    check_grip_session(s, typed, rate_tol=0.1)


LOSSY_CAL = [*LOOPBACK_CAL, "slide.repeats=0", "+hardware.faults.skin_board.p_drop_frame=0.05"]


def _skin_frames_missing(s) -> int:
    """Skin frames the file lacks between its first and last (gaps in the sequence numbers)."""
    d = np.diff(s.streams["skin"]["seq"])
    return int(np.sum(d[d > 1] - 1))


def test_lost_skin_frames_on_loopback_make_the_trial_incomplete(tmp_path, hydra_dirs):
    # The board's TX drops 5% of its frames: the driver counts the gaps, the file stores the
    # counts, and with the default max_lost_skin_frames=0 the trial is not complete.
    data = tmp_path / "data"
    r = run_cli("protocols.force_calibration", [*LOSSY_CAL, f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 1, r.stderr[-3000:]
    (partial,) = data.glob("force_calibration/*/*.mcap.partial")
    assert not list(data.glob("force_calibration/*/*.mcap"))
    s = load_session(partial, warn=False)
    skin = s.stream_health["skin"]
    assert skin["lost"] > 0 and _skin_frames_missing(s) > 0
    n = skin["lost"] + skin["dropped"]
    assert s.outcome == f"incomplete: {n} skin frames lost (limit max_lost_skin_frames=0)" and not s.complete
    assert "1 trial incomplete (pos000_press0: incomplete: " in r.stderr
    assert set(s.stream_health) == {"skin", "ft", "platform"}


def test_lost_skin_frames_within_the_limit_keep_the_trial_complete_and_recorded(tmp_path, hydra_dirs):
    data = tmp_path / "data"
    r = run_cli("protocols.force_calibration", [*LOSSY_CAL, "max_lost_skin_frames=1000000", f"data_root={data}",
                                                *hydra_dirs], tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    (f,) = data.glob("force_calibration/*/*.mcap*")
    s = load_session(f, warn=False)
    # complete, whatever ended the press (on a loaded host the platform's late ticks can carry the
    # press past the force limit: "complete (safety stop: ...)"), and not made incomplete by the loss
    assert s.complete and s.outcome.startswith("complete") and f.suffix == ".mcap"
    assert s.stream_health["skin"]["lost"] > 0 and _skin_frames_missing(s) > 0
    # rerun under the default limit (0): that file is not complete by this run's measure; it is
    # moved aside, not replaced, and the trial recorded again (lossy again: incomplete)
    recorded = f.read_bytes()
    r = run_cli("protocols.force_calibration", [*LOSSY_CAL, f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 1, r.stderr[-3000:]
    (aside,) = data.glob("force_calibration/*/*.mcap.over-limit")
    assert aside.read_bytes() == recorded and f"moved aside, not replaced: {aside.name}" in r.stdout


STALL_CASES = [  # (protocol, device, stream in the file, seconds after power-on)
    ("force_calibration", "skin_board", "skin", 2.5),
    ("force_calibration", "netft", "wrench", 2.5),
    ("force_calibration", "platform", "stage", 2.5),
    ("grip_depth", "ur5e", "tcp", 1.5),
    ("grip_depth", "hande", "gripper", 1.5),
]
RIG_NAME = {"skin_board": "skin", "netft": "ft", "platform": "platform", "ur5e": "arm", "hande": "gripper"}  # in faults


@pytest.mark.parametrize("app, device, stream, after_s", STALL_CASES)
def test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, app, device, stream, after_s):
    data = tmp_path / "data"
    base = LOOPBACK_CAL if app == "force_calibration" else ["hardware=loopback", *TINY_GRIP, "progress=false"]
    args = [*base, f"+hardware.faults.{device}.stall_after_s={after_s}", f"data_root={data}", *hydra_dirs]
    r = run_cli(f"protocols.{app}", args, tmp_path)
    assert r.returncode == 1, r.stderr[-3000:]
    (partial,) = data.glob(f"{app}/*/*.partial")
    s = load_session(partial, warn=False)
    assert not s.complete
    ev = s.streams["events"]
    (error,) = [d for k, d in zip(ev["kind"], ev["detail"], strict=True) if k == "error"]
    # the rig's watchdog latched the stall of this device, not another's (a command to the hung device
    # may fail first and end the trial; for the UR, ur_rtde then also drops the link)
    name = RIG_NAME[device]
    assert error["fault"].startswith(f"{name} stalled") or (device == "ur5e" and "link lost" in error["fault"]), error
    # motion was stopped within 50 ms of the device's last sign of life (its last sample in the file):
    # the rig's watchdog asks every device every 5 ms, whatever the protocol thread is doing. What
    # the host's scheduler adds is measured, not guessed, and allowed for: how late the watchdog's
    # latching check ran (check_late_ns) and, for a polled device, how late the poller sent the
    # request that went unanswered (beyond its poll period; the fault says when it went out)
    t_ns = s.streams[stream]["host_t_ns"]
    last_ns = int(t_ns[-1])
    late_ns = float(error.get("check_late_ns", 0))
    if device == "hande":
        # The Hand-E's driver polls its registers one GET at a time and writes a sample per full
        # round, so the file's last sample can precede the gripper's last answer by a round or
        # more (a round's GETs are answered, then it goes silent mid-round). Its last sign of life
        # is the last reply, which the fault dates ("no reply ... for N ms" when detected); the
        # stall is timed from there, and the file's last sample must not come after it.
        silent = re.search(r"no reply from the URCap socket for (\d+) ms", error["fault"])
        assert silent, error
        last_reply_ns = error["detected_ns"] - float(silent.group(1)) * 1e6
        assert last_ns <= last_reply_ns + 1e6, (last_ns, last_reply_ns)  # (the fault rounds to 1 ms)
        last_ns = int(last_reply_ns)
        # a poller the host ran late sent its next GET later than one poll period after the last reply
        sent = re.search(r"sent (\d+) ms after the last reply", error["fault"])
        if sent:
            late_ns += max(0.0, float(sent.group(1)) * 1e6 - 1e9 / HandEConfig().poll_rate_hz)
    caught = (error["detected_ns"] - last_ns) / 1e6
    print(f"{device} stall caught {caught:.1f} ms after its last sign of life, host lateness {late_ns / 1e6:.1f} ms")  # -rP
    assert error["detected_ns"] - last_ns <= 50e6 + 10e6 + late_ns, (caught, late_ns / 1e6)


def test_kill_9_during_a_loopback_trial_keeps_all_but_the_last_100_ms(tmp_path, hydra_dirs):
    data = tmp_path / "data"
    proc = popen_cli("protocols.force_calibration", [*LOOPBACK_CAL, f"data_root={data}", *hydra_dirs], tmp_path)
    try:
        deadline = time.monotonic() + 120
        partial = None
        while time.monotonic() < deadline and proc.poll() is None:
            found = list(data.glob("force_calibration/*/*.partial"))
            if found and found[0].stat().st_size > 200_000:
                partial = found[0]
                break
            time.sleep(0.05)
        assert partial is not None and proc.poll() is None, "no trial in progress to kill"
        t_kill = time.monotonic_ns()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
    s = load_session(partial, warn=False)
    assert not s.complete
    last_ns = int(s.streams["skin"]["host_t_ns"][-1])
    assert t_kill - last_ns <= 150e6  # ~100 ms flush interval, with margin for the kill itself


def test_standalone_emulator_prints_where_it_listens_and_serves(tmp_path):
    import socket
    import subprocess
    import sys

    from hardware.emulation import free_loopback_host
    from hardware.netft import NetFTConfig, NetFTSensor
    from tests.protocols.conftest import REPO

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    host = free_loopback_host({80: socket.SOCK_STREAM})  # the calibration page takes the box's port 80
    proc = subprocess.Popen([sys.executable, "-m", "hardware.emulate", "netft", "--host", host, "--port", "0"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith(f"netft emulator listening on {host}:"), line + proc.stderr.read()
        port = int(line.split()[4].rsplit(":", 1)[1])
        sensor = NetFTSensor(NetFTConfig(host=host, port=port, fetch_calibration=False))
        sensor.connect()
        try:
            deadline = time.monotonic() + 5
            samples = []
            while len(samples) < 50 and time.monotonic() < deadline:
                time.sleep(0.01)
                samples += sensor.read_available()
            assert len(samples) >= 50 and sensor.health.received >= 50
        finally:
            sensor.disconnect()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
