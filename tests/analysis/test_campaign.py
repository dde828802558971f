"""Reading a campaign: serial and parallel readers agree; unreadable files are skipped."""

import numpy as np


def test_campaign_reads_the_same_trials_in_parallel_and_skips_unreadable_files(tmp_path):
    import sys
    from pathlib import Path

    from analysis.sessions import CalibrationTrial, GripTrial, load_campaign

    sys.path.insert(0, str(Path(__file__).parent))
    from synthetic import calibration_trial, grip_trial

    rng = np.random.default_rng(4)
    for i, kind in enumerate(("press", "slide", "press")):
        calibration_trial(tmp_path / f"cal{i}.mcap", i, kind, 0, rng, n=120)
    grip_trial(tmp_path / "grip0.mcap", 9, "torsion", 0, rng, n=400)
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    serial = load_campaign(tmp_path, progress=False, workers=1)
    parallel = load_campaign(tmp_path, progress=False, workers=2)
    assert [t.name for t in serial.calibration] == ["cal0.mcap", "cal1.mcap", "cal2.mcap"]
    assert serial.skipped == parallel.skipped == {"unreadable file": 1}
    for a, b in zip(serial.calibration + serial.grip, parallel.calibration + parallel.grip, strict=True):
        assert type(a) is type(b) and a.name == b.name and a.labels == b.labels
        for k, v in vars(a).items():
            if isinstance(v, np.ndarray):
                np.testing.assert_array_equal(v, getattr(b, k), err_msg=k)
    assert isinstance(serial.calibration[0], CalibrationTrial) and isinstance(serial.grip[0], GripTrial)
    # The streams the analysis needs were read: forces, and arm and vision references of the grip.
    assert np.ptp(serial.calibration[0].force_n[:, 2]) > 1.0
    g = serial.grip[0]
    assert np.isfinite(g.arm_ref).all() and np.isfinite(g.vision_ref).all() and g.vision_t_s.size > 10
