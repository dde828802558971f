"""Where sessions go: every key that shapes the data is in the design folder or the file name,
a complete trial is never replaced by another, a reused sweep folder counts each job once."""

from __future__ import annotations

import json

import pytest
from omegaconf import OmegaConf

from protocols.calibration import run_campaign
from protocols.config import ForceCalibrationConfig
from protocols.grip import trial_name, trial_path
from protocols.identity import MANIFEST, design_id, trial_identity, write_manifest
from protocols.progress import LOG_FILE, PLAN_FILE, SweepProgress
from protocols.runner import RUN_FILES, TrialConflictError, run_trial
from protocols.sessions import describe
from tests.protocols.conftest import compose_app
from tests.protocols.fake_rig import platform_rig


def _grip(*overrides):
    cfg, typed = compose_app("grip_depth", list(overrides))
    config = OmegaConf.to_container(cfg, resolve=True)
    return typed, config


def test_design_folder_changes_with_every_protocol_and_sim_key():
    base_typed, base = _grip("grip_depth=9", "trial=5")
    for override in ("trajectory.translation.speed_mm_s=1", "trajectory.torsion.speed_deg_s=1", "hold_s=0.6",
                     "approach.threshold_counts=600", "sim.spacer.modulus_kpa=60", "seed=1"):
        typed, config = _grip("grip_depth=9", "trial=5", override)
        assert design_id(config) != design_id(base), override
        assert trial_path(typed, config) != trial_path(base_typed, base), override


def test_run_switches_and_the_motion_preset_keep_the_design(tmp_path):
    _, base = _grip("grip_depth=9")
    artifact = tmp_path / "T-s5.pt"
    artifact.write_bytes(b"")  # validation only checks that it is a file
    for override in ("save_images=true", f"estimator={artifact}", "sim.rig.camera.keep_images=true",
                     f"data_root={tmp_path}", "progress=false", "live=true", "trajectory=torsion",
                     "max_lost_skin_frames=100"):
        _, config = _grip("grip_depth=9", override)
        assert design_id(config) == design_id(base), override
    labels = {"grip_depth_mm": 9.0, "motion": "translation", "trial": 0}
    _, images = _grip("grip_depth=9", "save_images=true")
    assert trial_identity(images, labels) == trial_identity(base, labels)  # a view of the same trial


def test_images_come_from_one_switch():
    typed, _ = _grip("save_images=true")
    assert typed.sim.rig.camera.keep_images is True
    typed, _ = _grip()
    assert typed.sim.rig.camera.keep_images is False


def test_fault_injection_is_part_of_the_design():
    _, clean = _grip("hardware=loopback")
    _, faulty = _grip("hardware=loopback", "+hardware.faults.skin_board.p_bit_flip=0.001")
    _, other_port = _grip("hardware=loopback", "hardware.hande.port=1234")
    assert design_id(faulty) != design_id(clean) and design_id(other_port) == design_id(clean)


def test_a_changed_simulator_is_a_new_design_but_not_on_the_real_bench(monkeypatch):
    """Simulated sessions are shaped by the simulator's code: a rerun after it changes simulates
    into a new design folder (the old sessions stay) instead of resuming from the old code's data;
    on the real bench the simulator plays no part."""
    from layerskin_exp.sim import table_cache

    _, sim = _grip("grip_depth=9")
    _, loop = _grip("grip_depth=9", "hardware=loopback")
    _, lab = _grip("grip_depth=9", "hardware=lab")
    before = {k: design_id(c) for k, c in (("sim", sim), ("loopback", loop), ("lab", lab))}
    monkeypatch.setattr(table_cache, "_CODE_HASH", "0" * 64)  # as if the simulator's code had changed
    after = {k: design_id(c) for k, c in (("sim", sim), ("loopback", loop), ("lab", lab))}
    assert after["sim"] != before["sim"] and after["loopback"] != before["loopback"]
    assert after["lab"] == before["lab"]


def test_trial_names_keep_every_digit_of_the_grip_depth():
    names = {trial_name({"grip_depth_mm": d, "motion": "translation", "trial": 5}) for d in (9.0, 9.0000001, 9.5)}
    assert names == {"g9_translation_t5", "g9.0000001_translation_t5", "g9.5_translation_t5"}


def test_a_complete_trial_is_never_replaced_by_another_identity(tmp_path):
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    meta = {"config": {}, "backend": "fake"}

    def body(log):
        log.event("phase", "hold")

    first = run_trial(rig, path, {"trial": 0}, meta, body, identity="a" * 64)
    stamp = (path.stat().st_ino, path.stat().st_mtime_ns)
    with pytest.raises(TrialConflictError, match="not replaced"):
        run_trial(rig, path, {"trial": 0}, meta, body, identity="b" * 64)
    again = run_trial(rig, path, {"trial": 0}, meta, body, identity="a" * 64)
    assert first.outcome == "complete" and again.skipped
    assert (path.stat().st_ino, path.stat().st_mtime_ns) == stamp
    assert not list(tmp_path.glob("*.partial"))


def test_a_rerun_asking_for_images_skips_the_complete_trial_and_says_what_it_lacks(tmp_path, caplog):
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    run_trial(rig, path, {}, {"config": {"save_images": False}}, lambda log: None, identity="a" * 64)
    again = run_trial(rig, path, {}, {"config": {"save_images": True}}, lambda log: None, identity="a" * 64)
    assert again.skipped and "recorded with save_images=False" in again.summary()
    assert any("already complete" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)


def test_a_campaign_with_a_conflicting_file_refuses_before_its_first_trial(tmp_path):
    # The same folder and names but a different plan (here: the slides' vertical offsets), as when
    # the planning code changes between two runs: nothing runs, nothing is replaced.
    def cfg(z_offset_mm):
        c = ForceCalibrationConfig(hardware={}, skin={}, data_root=str(tmp_path), progress=False)
        c.positions.count, c.press.repeats, c.slide.repeats, c.slide.z_offset_mm = 2, 1, 1, z_offset_mm
        return c

    meta = {"config": {}, "backend": "fake"}
    rig = platform_rig(mu=0.9)
    rig.connect()
    run_campaign(cfg(0.5), rig, meta)
    files = sorted((tmp_path / "force_calibration").glob("*/*.mcap"))
    stamps = [f.stat().st_mtime_ns for f in files]
    with pytest.raises(TrialConflictError):
        run_campaign(cfg(0.2), rig, meta)
    assert [f.stat().st_mtime_ns for f in files] == stamps
    assert sorted((tmp_path / "force_calibration").glob("*/*.mcap*")) == files


def test_a_reused_sweep_folder_counts_this_runs_jobs_once(tmp_path, capsys):
    # The same sweep run again into its folder: the earlier run's lines stay in the log.
    (tmp_path / PLAN_FILE).write_text(json.dumps({"n_jobs": 2, "t0_unix_s": 0.0, "run": "second"}))
    old = [{"run": "first", "job": j, "ok": True, "result": {"skipped": False}} for j in (0, 1)]
    new = [{"run": "second", "job": 0, "ok": True, "result": {"skipped": True}}] * 2  # reported twice
    (tmp_path / LOG_FILE).write_text("".join(json.dumps(r) + "\n" for r in old + new))
    with pytest.raises(SystemExit) as end:  # a job that never reported may have been killed
        SweepProgress().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path)}}}))
    assert end.value.code == 1
    out = capsys.readouterr().out
    assert "0 ran, 1 already complete, 0 failed, 1 not reported" in out


def test_sessions_listing_names_what_tells_designs_apart(tmp_path):
    root = tmp_path / "grip_depth"
    for modulus in (20.0, 60.0):
        config = {"sim": {"spacer": {"modulus_kpa": modulus}}, "hold_s": 0.5, "trial": 0}
        folder = root / design_id(config)
        write_manifest(folder, config)
        (folder / "g6_translation_t0.mcap").write_bytes(b"")
    (root / design_id({"sim": {"spacer": {"modulus_kpa": 20.0}}, "hold_s": 0.5}) / "g6_translation_t1.mcap.partial") \
        .write_bytes(b"")
    text = describe(tmp_path)
    assert "2 design(s), differing in sim.spacer.modulus_kpa" in text
    assert "1 complete, 1 interrupted  sim.spacer.modulus_kpa=20.0" in text
    assert "1 complete, 0 interrupted  sim.spacer.modulus_kpa=60.0" in text
    assert all((root / d / MANIFEST).is_file() for d in [p.name for p in root.iterdir()])


def test_sessions_listing_tells_a_trial_being_written_from_an_interrupted_one(tmp_path):
    """A `.partial` whose writer still holds its lock is in progress; one nobody holds (its run
    crashed or was killed: the kernel dropped the lock) is interrupted."""
    from layerskin_exp.log import SessionWriter

    folder = tmp_path / "grip_depth" / design_id({"hold_s": 0.5})
    write_manifest(folder, {"hold_s": 0.5})
    (folder / "g6_translation_t0.mcap.partial").write_bytes(b"")  # left by a killed run
    writer = SessionWriter(folder / "g6_translation_t1.mcap.partial", metadata={"config": {}, "backend": "sim"})
    try:
        assert "0 complete, 1 in progress, 1 interrupted" in describe(tmp_path)
    finally:
        writer.close()
    assert "0 complete, 2 interrupted" in describe(tmp_path)  # closed, not renamed: nobody writes it now


def _first_chunk(data: bytes) -> int:
    off = 8  # after the magic: records are opcode (1 byte), length (u64), body
    while data[off] != 0x06:
        off += 9 + int.from_bytes(data[off + 1:off + 9], "little")
    return off


def _flip(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x5A
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", ["closing magic", "inside a chunk"])
def test_a_damaged_trial_of_another_identity_is_not_replaced(tmp_path, damage):
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    meta = {"config": {}, "backend": "fake"}

    def body(log):
        for _ in range(20):
            rig.clock.sleep(0.005)
            log.drain()

    run_trial(rig, path, {"trial": 0}, meta, body, identity="a" * 64)
    data = path.read_bytes()
    _flip(path, len(data) - 3 if damage == "closing magic" else _first_chunk(data) + 60)
    before = path.read_bytes()
    with pytest.raises(TrialConflictError, match="damaged trial recorded with another configuration"):
        run_trial(rig, path, {"trial": 0}, meta, body, identity="b" * 64)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["t.mcap"]


def test_a_damaged_file_whose_identity_cannot_be_read_is_moved_aside_and_reported(tmp_path, caplog):
    rig = platform_rig()
    rig.connect()
    path = tmp_path / "t.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + bytes(64))  # a header and nothing readable
    (tmp_path / "t.mcap.damaged").write_bytes(b"an earlier one")
    RUN_FILES.reset()
    result = run_trial(rig, path, {"trial": 0}, {"config": {}}, lambda log: None, identity="b" * 64)
    assert result.outcome == "complete"
    assert (tmp_path / "t.mcap.damaged-1").read_bytes() == b"\x89MCAP0\r\n" + bytes(64)
    assert (tmp_path / "t.mcap.damaged").read_bytes() == b"an earlier one"
    assert "moved aside, not replaced: t.mcap.damaged-1" in RUN_FILES.line()
    assert any("t.mcap.damaged-1" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)
