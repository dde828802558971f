"""The one control loop: a stalled stream stops all motion within 50 ms and closes the trial
aborted; faults reported from driver threads end the trial the same way."""

from __future__ import annotations

import numpy as np
import pytest

from hardware.interfaces import DeviceError
from layerskin_exp.log import load_session
from protocols.calibration import run_campaign
from protocols.config import ForceCalibrationConfig
from protocols.loop import DeviceFault
from tests.protocols.fake_rig import platform_rig

META = {"config": {}, "backend": "fake"}


def _cfg(tmp_path) -> ForceCalibrationConfig:
    cfg = ForceCalibrationConfig(hardware={}, skin={}, data_root=str(tmp_path), progress=False)
    cfg.positions.count, cfg.press.repeats, cfg.slide.repeats = 1, 1, 1
    return cfg


def test_stalled_skin_stops_motion_within_50_ms_and_aborts(tmp_path):
    rig = platform_rig(skin_stalls_after_s=1.0)
    rig.connect()
    cfg = _cfg(tmp_path)
    with pytest.raises(DeviceFault, match="skin stalled"):
        run_campaign(cfg, rig, META)
    last_frame_ns = rig.skin.last_rx_ns
    # every stop() call counts; the first after the stall is the loop's safe stop
    stops = [t for t in rig.platform.stopped_at_ns if t > last_frame_ns]
    assert stops, "motion was never stopped"
    assert stops[0] - last_frame_ns <= 50_000_000  # stall timeout 40 ms + at most one 10 ms tick
    assert not rig.platform.is_moving()
    (partial,) = (tmp_path / "force_calibration").glob("*/*.partial")
    s = load_session(partial, warn=False)
    assert s.outcome.startswith("aborted: skin stalled") and not s.complete
    # nothing acquired before the stall was lost
    assert s.streams["skin"]["t_ns"][-1] == last_frame_ns


def test_fault_reported_from_another_thread_ends_the_trial(tmp_path):
    import threading

    rig = platform_rig()
    rig.connect()
    cfg = _cfg(tmp_path)
    reporter = threading.Timer(0.0, rig.report_fault, args=("ft: link lost (connection reset)",))
    reporter.start()
    reporter.join()
    assert not rig.platform.is_moving()
    with pytest.raises(DeviceError, match="ft: link lost"):
        run_campaign(cfg, rig, META)
    (partial,) = (tmp_path / "force_calibration").glob("*/*.partial")
    assert load_session(partial, warn=False).outcome == "aborted: ft: link lost (connection reset)"


def test_guards_watch_any_stream():
    rig = platform_rig()
    rig.connect()
    rig.add_guard(lambda f: "skin overload" if int(f.superficial.max()) > 30 else None, stream="skin")
    rig.platform.move_to(np.array([0.0, 0.0, -10.0]), 1.0)
    for _ in range(400):  # 4 s of fake time: the tip presses in until the skin guard trips
        rig.clock.sleep(0.01)
        if rig.tripped:
            break
    assert rig.tripped == "skin overload"
    assert not rig.platform.is_moving()
