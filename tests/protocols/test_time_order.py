"""Session files are written in log-time order: a streaming reader (the official `mcap` reader on
a stream it cannot seek, as `mcap cat` or a live tail reads) sees time run forward on every
channel and across the whole file, calibration and grip alike (issue 32)."""

from __future__ import annotations

import io
from collections import Counter
from datetime import datetime, timezone

from mcap.reader import NonSeekingReader, make_reader
from omegaconf import OmegaConf

from hardware import build_rig
from protocols.grip import run_grip_trial
from tests.protocols.conftest import TINY_GRIP, compose_app
from tests.protocols.test_resume import START, START_NS, _campaign


class _Stream(io.RawIOBase):
    """A file read front to back only (a pipe): the reader cannot reach the summary or index."""

    def __init__(self, data: bytes) -> None:
        self._data, self._pos = data, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False

    def readinto(self, buf) -> int:
        n = min(len(buf), len(self._data) - self._pos)
        buf[:n] = self._data[self._pos:self._pos + n]
        self._pos += n
        return n


def _backward_steps(path) -> tuple[Counter, int, int]:
    """(per topic: messages earlier than the one before on that topic, the same over the whole
    file, messages), read in file order without the index."""
    reader = make_reader(io.BufferedReader(_Stream(path.read_bytes())))
    assert isinstance(reader, NonSeekingReader)
    per_topic, last, whole, prev, n = Counter(), {}, 0, None, 0
    for _, channel, msg in reader.iter_messages(log_time_order=False):  # as written, not sorted
        n += 1
        if msg.log_time < last.get(channel.topic, msg.log_time):
            per_topic[channel.topic] += 1
        last[channel.topic] = msg.log_time
        whole += prev is not None and msg.log_time < prev
        prev = msg.log_time
    return per_topic, whole, n


def test_a_resumed_calibration_campaign_is_in_log_time_order_and_dated_on_its_day(tmp_path):
    _campaign(tmp_path, stop_at=1)
    _, folder = _campaign(tmp_path)
    files = sorted(folder.glob("*.mcap"))
    assert len(files) == 4
    day = datetime.fromisoformat(START.replace("Z", "+00:00")).date()
    for path in files:
        per_topic, whole, n = _backward_steps(path)
        assert n > 1000 and not per_topic and whole == 0, (path.name, per_topic, whole)
        with open(path, "rb") as f:
            first = min(m.log_time for _, _, m in make_reader(f).iter_messages())
        assert first >= START_NS and datetime.fromtimestamp(first / 1e9, timezone.utc).date() == day


def test_a_grip_trial_is_in_log_time_order(tmp_path):
    cfg, typed = compose_app("grip_depth", [*TINY_GRIP, f"data_root={tmp_path}", f"sim.rig.start_time={START}",
                                            "progress=false"])
    with build_rig(cfg, "gripper") as rig:
        result = run_grip_trial(typed, rig, {"config": OmegaConf.to_container(cfg, resolve=True), "backend": "sim"})
    per_topic, whole, n = _backward_steps(tmp_path.__class__(result.path))
    assert n > 1000 and not per_topic and whole == 0, (per_topic, whole)
