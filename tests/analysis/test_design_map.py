"""The design map: a tiny design sweep through the submitit_local launcher (the cluster path run by a
real engine), its resume, and the map measured from it; the ranking logic on synthetic outcomes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from analysis.design_map import DesignMapConfig, build_map, command, run
from tests.protocols.conftest import REPO, run_cli

TINY = ["positions.count=2", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05", "progress=false"]


# slow: a design sweep through submitit_local (a job process each, its resume, the map): ~40 s.
@pytest.mark.slow
def test_sweep_through_submitit_local_resumes_and_maps(tmp_path, hydra_dirs):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    data = tmp_path / "data"
    args = ["-m", "+design=study,stiff_interlayer", "+bracket=nominal", *TINY, f"data_root={data}",
            "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10", *hydra_dirs]
    r = run_cli("protocols.force_calibration", args, tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    files = sorted((data / "force_calibration").glob("*/*.mcap"))
    assert len(files) == 2 * 2 * 2  # two designs, each its own folder of 2 positions x (1 press + 1 slide)
    assert len({f.parent for f in files}) == 2
    stamps = {f: f.stat().st_mtime_ns for f in files}
    r = run_cli("protocols.force_calibration", args, tmp_path)  # resume: nothing left to run
    assert r.returncode == 0, r.stderr[-3000:]
    assert {f: f.stat().st_mtime_ns for f in files} == stamps

    out = tmp_path / "map"
    res = run(DesignMapConfig(sweep_dir=str(data), out=str(out), min_frames=10))
    designs = res["map"]["designs"]
    assert set(designs) == {"study", "stiff_interlayer"}
    study = designs["study"]["brackets"]["nominal"]
    stiff = designs["stiff_interlayer"]["brackets"]["nominal"]
    # The map measures each design from its own sessions. Which design shears more, the shift's sign
    # (the leading layer) and whether a design resolves shear at all (smallest resolvable shear below
    # the largest applied) are results the map reports (docs/design-map), not conditions of this
    # test: the measurement itself is checked against known answers in
    # test_the_resolvable_shear_is_measured_not_assumed.
    for d in (study, stiff):
        assert np.isfinite(d["shift_per_n_mm"]) and d["shift_per_n_mm"] != 0
        assert d["zero_shear_shift_rms_mm"] > 0 and d["shear_high_n"] > 0, d
        sigmas = DesignMapConfig().noise_sigmas
        assert d["shear_low_n"] == pytest.approx(sigmas * d["zero_shear_shift_rms_mm"] / abs(d["shift_per_n_mm"])), d
    assert study["densification_n"] is not None and np.isfinite(study["densification_n"])
    saved = json.loads((out / "design_map.json").read_text())
    assert set(saved["map"]["designs"]) == {"study", "stiff_interlayer"}
    md = (out / "design_map.md").read_text()
    assert "| study ★ |" in md and "| stiff_interlayer |" in md and "settle" in md
    assert (out / "design_map.png").stat().st_size > 10_000


@pytest.mark.parametrize("h_mm, resolves", [(2.0, True), (0.0, False)])
def test_the_resolvable_shear_is_measured_not_assumed(tmp_path, h_mm, resolves):
    """Synthetic campaigns whose layers separate by h·F_shear/F_z: with h = 2 mm the map finds the
    closed-form shift per newton at the slides' 3 N preload (h/F_z, the superficial layer leading
    along the shear, so d_par = -h/F_z) and a smallest resolvable shear below the applied 2 N; with
    h = 0 the same measurement finds no resolvable shear (whatever range it reads)."""
    from analysis.design_map import campaign_outcomes
    from tests.analysis.synthetic import write_campaign

    root = write_campaign(tmp_path / "camp", n_positions=4, grip_depths=(), h_mm=h_mm)
    o = campaign_outcomes(root / "force_calibration", DesignMapConfig(sweep_dir=str(tmp_path), min_frames=10,
                                                                      ts5=False, progress=False))
    if resolves:
        assert o["shear_high_n"] == pytest.approx(2.0, abs=0.05)  # the slides' applied shear
        assert o["shift_per_n_mm"] == pytest.approx(-h_mm / 3.0, rel=0.2), o["shift_per_n_by_fz"]
        assert o["shear_low_n"] < o["shear_high_n"], o
    else:
        assert abs(o["shift_per_n_mm"]) < 0.05, o["shift_per_n_by_fz"]
        assert o["shear_low_n"] is None or o["shear_low_n"] > o["shear_high_n"], o


def _outcome(design: str, bracket: str, shift: float, high: float) -> dict:
    return {"overrides": [f"+design={design}", f"+bracket={bracket}"], "config": {"sim": {"spacer": {"modulus_kpa": 1}}},
            "shift_per_n_mm": shift, "shear_high_n": high}


def test_rankings_only_where_they_hold_in_every_bracket():
    outs = [_outcome("a", "nominal", 2.0, 1.0), _outcome("b", "nominal", 1.0, 2.0),
            _outcome("a", "bonded", 1.5, 1.0), _outcome("b", "bonded", 1.6, 1.9)]
    r = build_map(outs)["rankings"]
    # shift: a wins nominally, b when bonded -> no robust winner, no pair holds
    assert r["shift_per_n_mm"]["best_in_every_bracket"] is None
    assert r["shift_per_n_mm"]["pairs_that_hold"] == []
    assert r["shift_per_n_mm"]["best_by_bracket"] == {"nominal": "a", "bonded": "b"}
    # range: b wins in both
    assert r["shear_high_n"]["best_in_every_bracket"] == "b"
    assert r["shear_high_n"]["pairs_that_hold"] == [["b", "a"]]
    bands = build_map(outs)["designs"]["a"]["bands"]
    assert bands["shift_per_n_mm"] == [1.5, 2.0]


def test_the_shift_ranks_by_magnitude_whichever_layer_leads():
    # c's superficial CoP leads (negative shift) by more than a's deep CoP: c resolves shear better
    outs = [_outcome("a", "nominal", 1.0, 1.0), _outcome("c", "nominal", -2.0, 1.0)]
    r = build_map(outs)["rankings"]["shift_per_n_mm"]
    assert r["order_by_bracket"] == {"nominal": ["c", "a"]}
    assert build_map(outs)["designs"]["c"]["bands"]["shift_per_n_mm"] == [-2.0, -2.0]  # reported signed


def test_bad_arguments_are_one_line_and_exit_2(tmp_path, capsys):
    # through the command line (a subprocess: under pytest `protocols` can name the tests' package)
    r = run_cli("analysis.design_map", [f"sweep_dir={tmp_path}", "noise_sigmas=abc"], tmp_path)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "noise_sigmas" in err[0], r.stderr
    r = run_cli("analysis.design_map", [f"sweep_dir={tmp_path}/nowhere"], tmp_path)
    assert r.returncode == 2 and "sweep_dir=" in r.stderr and not (tmp_path / "nowhere").exists()
    assert command(DesignMapConfig(sweep_dir=str(tmp_path))) == 2  # an empty folder: nothing to map
    assert "no force_calibration sessions" in capsys.readouterr().err


def test_a_campaign_recorded_under_a_renamed_key_is_refused_in_one_line(tmp_path, capsys):
    """A sweep recorded before the spacer's keys carried units: its sessions' configs name
    `sim.spacer.modulus`; the map refuses it naming the new key rather than failing on it."""
    from tests.analysis.synthetic import calibration_trial

    folder = tmp_path / "force_calibration" / "0123456789"
    folder.mkdir(parents=True)
    calibration_trial(folder / "pos000_press0.mcap", 0, "press", 0, np.random.default_rng(0), n=60,
                      config={"sim": {"spacer": {"modulus": 35.0, "thickness": 2.5}}})
    assert command(DesignMapConfig(sweep_dir=str(tmp_path), figures=False, progress=False)) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "sim.spacer.modulus" in err and "renamed to sim.spacer.modulus_kpa" in err and "rerun" in err, err


def test_design_groups_compose():
    """Every design and bracket composes into a valid calibration config (preflight's check)."""
    designs = sorted(p.stem for p in (REPO / "conf" / "design").glob("*.yaml"))
    brackets = sorted(p.stem for p in (REPO / "conf" / "bracket").glob("*.yaml"))
    assert len(designs) >= 8 and {"study", "stiff_interlayer"} <= set(designs)
    # each design with the nominal bracket, each bracket with the study's design (not the product: slow)
    code = ("import sys; import protocols.config; "
            "from layerskin_exp.cli import preflight; d, b = sys.argv[1:]; "
            "preflight('force_calibration', ['-m', '+design=' + d, '+bracket=nominal']); "
            "preflight('force_calibration', ['-m', '+design=study', '+bracket=' + b]); print('ok')")
    r = subprocess.run([sys.executable, "-c", code, ",".join(designs), ",".join(brackets)], cwd=REPO,
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]
    r = subprocess.run([sys.executable, "-c", code, "nonesuch", "nominal"], cwd=REPO, capture_output=True,
                       text=True, timeout=240)
    assert r.returncode == 2 and "nonesuch" in r.stderr


def test_design_search_sweeper_composes(tmp_path):
    """The Optuna search config as the app resolves it: NSGA-II, two maximised objectives, the
    spacer's four keys (in a subprocess: under pytest `protocols` can name the tests' package)."""
    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper")
    r = run_cli("protocols.design_search", ["--cfg", "hydra", "hydra/sweeper=design_search"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    sweeper = r.stdout[r.stdout.index("sweeper:"):]
    assert "_target_: optuna.samplers.NSGAIISampler" in sweeper
    assert "direction:\n    - maximize\n    - maximize" in sweeper
    for key in ("sim.spacer.modulus_kpa", "sim.spacer.thickness_mm", "sim.spacer.cell_mm", "sim.spacer.wall_mm"):
        assert f"{key}:" in sweeper


def test_position_folds_never_share_a_position():
    from analysis.design_map import position_folds

    groups = np.repeat(np.arange(6), 10)
    splits = position_folds(groups, 4)
    assert len(splits) == 4
    for tr, te in splits:
        assert not set(groups[tr]) & set(groups[te])
    assert sorted(np.concatenate([te for _, te in splits]).tolist()) == list(range(60))  # every frame tested once
    assert len(position_folds(groups, 10)) == 6  # one position per fold when there are fewer positions
    assert position_folds(np.zeros(5), 4) == []


def test_ts5_per_design_on_a_synthetic_campaign_is_flagged_when_unconverged(tmp_path):
    """A tiny T-s5 on the same position folds as the linear model; one epoch is the epoch cap, so
    the report's flag marks it unconverged and the map shows that beside its R²."""
    from analysis.design_map import campaign_outcomes
    from layerskin_exp.estimation.config import CnnConfig
    from tests.analysis.synthetic import write_campaign

    root = write_campaign(tmp_path / "camp", n_positions=4, grip_depths=())
    tiny = CnnConfig(configurations=["T-s5"], batch_size=32, segment_windows=8, max_epochs=1, max_train_windows=128,
                     torch_threads=1)
    cfg = DesignMapConfig(sweep_dir=str(tmp_path), min_frames=10, folds=2, cnn=tiny)
    o = campaign_outcomes(root / "force_calibration", cfg)
    assert o["folds"] == 2
    assert set(o["ts5_r2"]) == {"x", "y", "z"} and all(np.isfinite(o["ts5_r2"][a]) for a in "xyz")
    assert o["ts5_r2_shear"] == pytest.approx(np.mean([o["ts5_r2"]["x"], o["ts5_r2"]["y"]]))
    tr = o["ts5_training"]
    assert len(tr["folds"]) == 2 and all(f["epochs"] == 1 for f in tr["folds"])
    assert tr["converged"] is False and any("epoch cap" in c for c in tr["caveats"])
    o["overrides"] = ["+design=study", "+bracket=nominal"]
    m = build_map([o])
    from analysis.design_map import _ts5_cell

    cell = _ts5_cell(m["designs"]["study"])
    assert "†" in cell and "(1/1 unconverged)" in cell
    o["ts5_training"] = {**tr, "converged": True, "caveats": []}  # the same numbers, converged: no mark
    assert "†" not in _ts5_cell(build_map([o])["designs"]["study"])
    cfg.ts5 = False
    assert "ts5_r2" not in campaign_outcomes(root / "force_calibration", cfg)


def test_the_loading_ramp_starts_at_contact_not_at_a_pre_tare_offset():
    """A press's wrench reads the sensor's offset until the trial's tare at the clearance height
    (0.15 N here, in the air): first contact is where F_z rises through the touch level for the
    last time before the peak, not the first sample above it."""
    from analysis.design_map import loading_ramp

    z = np.concatenate([np.full(50, 5.0), np.linspace(5.0, 0.0, 100), np.linspace(0.0, -2.0, 100)])
    fz = np.concatenate([np.full(50, 0.15), np.full(40, 0.15), np.zeros(60), np.linspace(0.0, 4.0, 100)])
    travel, f = loading_ramp(z, fz)
    assert f[0] >= 0.05 and travel[0] == 0.0
    assert travel[-1] == pytest.approx(2.0 - 2.0 / 99, abs=0.03)  # the contact's travel, not the approach's
    assert loading_ramp(z, np.zeros_like(z)) is None
