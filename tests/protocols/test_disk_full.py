"""A disk that fills up during a trial: the run stops naming the file it could not write and the
trial it interrupted, keeps what reached the disk, and counts the trial as interrupted."""

from __future__ import annotations

import errno

import pytest

from layerskin_exp.log.session import writer as writer_module
from protocols.calibration import run_campaign
from protocols.config import ForceCalibrationConfig
from protocols.runner import RUN_FILES
from tests.protocols.fake_rig import platform_rig

META = {"config": {}, "backend": "fake"}


class FullDisk:
    """A file that takes `room` bytes, then fails every write and flush with ENOSPC."""

    def __init__(self, raw, room: int) -> None:
        self.raw, self.room = raw, room

    def write(self, data) -> int:
        if len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.raw.write(data)

    def flush(self) -> None:
        if self.room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.raw.flush()

    def close(self) -> None:
        self.raw.close()

    def __getattr__(self, name):
        return getattr(self.raw, name)


@pytest.fixture
def full_disk(monkeypatch):
    """The next session file gets this many bytes before the disk is full."""
    def fill_after(room: int) -> None:
        open_fd = writer_module._open_fd
        monkeypatch.setattr(writer_module, "_open_fd", lambda fd: FullDisk(open_fd(fd), room))
    return fill_after


def test_a_full_disk_mid_trial_names_the_file_and_counts_the_trial_interrupted(tmp_path, full_disk):
    cfg = ForceCalibrationConfig(hardware={}, skin={}, data_root=str(tmp_path), progress=False)
    cfg.positions.count, cfg.press.repeats, cfg.slide.repeats = 1, 1, 0
    rig = platform_rig()
    rig.connect()
    RUN_FILES.reset()
    full_disk(200_000)  # the header and a few chunks fit
    with pytest.raises(OSError) as stop:
        run_campaign(cfg, rig, META)
    (partial,) = tmp_path.rglob("pos000_press0.mcap.partial")
    assert stop.value.errno == errno.ENOSPC and stop.value.filename == str(partial)
    assert str(stop.value) == f"[Errno 28] No space left on device: '{partial}'"
    assert not rig.platform.is_moving()
    assert RUN_FILES.interrupted == [partial] and partial.stat().st_size > 0
    assert RUN_FILES.stop_note() == "the trial in progress is kept as pos000_press0.mcap.partial (aborted)"
    assert ", 1 interrupted (kept as .mcap.partial; a rerun runs it again)" in RUN_FILES.line()
    RUN_FILES.reset()


def test_the_app_says_which_file_and_trial_a_full_disk_stopped(tmp_path, monkeypatch, capsys, full_disk):
    from protocols.app import run_app
    from protocols.calibration import run_campaign as campaign
    from tests.protocols.conftest import TINY_CALIBRATION, compose_app

    monkeypatch.setattr("hardware.build_rig", lambda cfg, setup: platform_rig())
    cfg, _ = compose_app("force_calibration", [*TINY_CALIBRATION, f"data_root={tmp_path}"])
    full_disk(200_000)
    with pytest.raises(SystemExit) as stop:
        run_app(cfg, "platform", campaign)
    assert stop.value.code == 1
    out, err = capsys.readouterr()
    (partial,) = tmp_path.rglob("*.mcap.partial")
    assert err.strip().splitlines()[-1] == (
        f"error: OSError: [Errno 28] No space left on device: '{partial}' (motion stopped, the trial in progress "
        f"is kept as {partial.name} (aborted); rerun the same command to resume)")
    assert out.splitlines()[-1].startswith("0 session files written to ")
    assert ", 1 interrupted (kept as .mcap.partial" in out.splitlines()[-1]
