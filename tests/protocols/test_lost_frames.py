"""Every trial stores what each device's driver counted over it; a trial whose skin lost more
frames than `max_lost_skin_frames` allows is incomplete: kept as .partial, saying why."""

from __future__ import annotations

import pytest

from layerskin_exp.log import load_session
from protocols.runner import RUN_FILES, run_trial
from tests.protocols.fake_rig import platform_rig

META = {"config": {}, "backend": "fake"}


def _lossy_trial(lost: int, dropped: int = 0):
    """A trial body during which the skin driver counts `lost` sequence gaps (and `dropped` frames
    its full buffer let go, as the skin board driver's ring_dropped)."""

    def body(log):
        log.event("phase", "hold")
        log.rig.skin.health.lost += lost
        log.rig.skin.health.received += 100
        if dropped:
            log.rig.skin.ring_dropped = getattr(log.rig.skin, "ring_dropped", 0) + dropped

    return body


def test_counters_are_the_trials_own_and_stored_in_every_session(tmp_path):
    rig = platform_rig()
    rig.connect()
    rig.skin.health.lost, rig.ft.health.corrupt = 50, 4  # counted before this trial: not its own
    r = run_trial(rig, tmp_path / "t.mcap", {"trial": 0}, META, _lossy_trial(0))
    s = load_session(r.path, warn=False)
    assert r.outcome == "complete" and s.complete
    assert set(s.stream_health) == {"skin", "ft", "platform"}
    assert s.stream_health["skin"] == {"received": 100, "lost": 0, "duplicate": 0, "out_of_order": 0, "corrupt": 0,
                                       "reconnects": 0}
    assert s.stream_health["ft"]["corrupt"] == 0


@pytest.mark.parametrize("lost, dropped, limit, complete", [
    (7, 0, 0, False), (7, 0, 6, False), (7, 0, 7, True), (7, 0, 1000, True), (4, 3, 6, False), (0, 0, 0, True)])
def test_more_lost_skin_frames_than_the_limit_make_the_trial_incomplete(tmp_path, lost, dropped, limit, complete):
    RUN_FILES.reset()
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    r = run_trial(rig, path, {"trial": 0}, META, _lossy_trial(lost, dropped), max_lost_skin_frames=limit)
    s = load_session(r.path, warn=False)
    assert s.stream_health["skin"]["lost"] == lost and s.stream_health["skin"].get("dropped", 0) == dropped
    if complete:
        assert r.outcome == "complete" and s.complete and r.path == str(path)
        assert RUN_FILES.incomplete == [] and RUN_FILES.written == 1
        return
    why = f"incomplete: {lost + dropped} skin frames lost (limit max_lost_skin_frames={limit})"
    assert r.outcome == why and s.outcome == why and not s.complete
    assert r.path == str(path) + ".partial" and not path.exists()  # a rerun records it again
    assert RUN_FILES.incomplete == [f"t: {why}"] and RUN_FILES.written == 0
    assert "1 incomplete" in RUN_FILES.line() and why in RUN_FILES.line()
    again = run_trial(rig, path, {"trial": 0}, META, _lossy_trial(0), max_lost_skin_frames=limit)
    assert again.outcome == "complete" and path.is_file() and not again.skipped


def test_a_complete_trial_is_judged_again_by_a_stricter_limit(tmp_path, caplog):
    # Written complete under max_lost_skin_frames=10 with 7 frames lost: a rerun under the same
    # limit skips it; one under 5 finds it not complete by its measure, moves it aside (never
    # replaced, reported) and records the trial again.
    from protocols.runner import trial_is_complete

    RUN_FILES.reset()
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    run_trial(rig, path, {"trial": 0}, META, _lossy_trial(7), max_lost_skin_frames=10)
    first = path.read_bytes()
    assert trial_is_complete(path, None, 10) and trial_is_complete(path, None, 7) and trial_is_complete(path)
    assert not trial_is_complete(path, None, 6)
    again = run_trial(rig, path, {"trial": 0}, META, _lossy_trial(0), max_lost_skin_frames=10)
    assert again.skipped and path.read_bytes() == first
    RUN_FILES.reset()
    stricter = run_trial(rig, path, {"trial": 0}, META, _lossy_trial(0), max_lost_skin_frames=5)
    assert not stricter.skipped and stricter.outcome == "complete"
    assert (tmp_path / "t.mcap.over-limit").read_bytes() == first
    assert load_session(path, warn=False).stream_health["skin"]["lost"] == 0
    assert "moved aside" in RUN_FILES.line() and "t.mcap.over-limit" in RUN_FILES.line()
    assert any("lost 7 skin frames" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)
