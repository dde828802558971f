"""The sensitivity screen: brackets to a SALib problem, Morris effects in the outcome's unit per
bracket, and a real (tiny) screen in which a parameter moves only the outcome it can move."""

from __future__ import annotations

import json

import numpy as np
import pytest

from layerskin_exp.config import ConfigError
from protocols import sensitivity as sens


def test_brackets_file_gives_a_problem_with_every_screened_entry():
    b = sens.load_brackets()
    prob = sens.problem(b)
    screened = [k for k, v in b.items() if v.get("screen", True)]
    assert prob["names"] == screened and "sim.rig.camera.latency_ms" not in screened
    for k, v in b.items():  # each entry sourced or bracketed, with its nominal inside the bracket
        assert v.get("source"), k
        if "levels" in v:
            assert v["nominal"] in v["levels"], k
        else:
            assert v["low"] <= v["nominal"] <= v["high"], k
    row = np.array([lo for lo, _ in prob["bounds"]])
    ov = sens.overrides_for(row, prob, b)
    assert "sim.sheet.interface=unbonded" in ov and "sim.cover.friction=0.6" in ov
    ov = sens.overrides_for(np.array([hi for _, hi in prob["bounds"]]), prob, b)
    assert "sim.sheet.interface=bonded" in ov


def test_a_bracket_without_its_source_or_outside_its_bounds_is_refused_by_name(tmp_path):
    good = "parameters:\n  sim.cover.friction: {nominal: 1.0, low: 0.6, high: 1.5, source: bracket}\n"
    (tmp_path / "ok.yaml").write_text(good)
    assert sens.load_brackets(tmp_path / "ok.yaml")["sim.cover.friction"]["high"] == 1.5
    for bad in ("{nominal: 2.0, low: 0.6, high: 1.5, source: bracket}", "{nominal: 1.0, low: 0.6, high: 1.5}",
                "{nominal: glued, levels: [bonded, unbonded], source: bracket}"):
        (tmp_path / "bad.yaml").write_text(f"parameters:\n  sim.cover.friction: {bad}\n")
        with pytest.raises(ConfigError, match="sim.cover.friction"):
            sens.load_brackets(tmp_path / "bad.yaml")


def test_unknown_parameter_is_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match="params=sim.cover.frition"):
        sens.problem(sens.load_brackets(), ["sim.cover.frition"])
    with pytest.raises(ConfigError, match="params=sim.cover.frition"):  # the schema checks it
        sens.SensitivityConfig(params=["sim.cover.frition"])
    # the command line refuses it in one line, before any campaign
    from tests.protocols.conftest import run_cli

    r = run_cli("protocols.sensitivity", ["params=[sim.cover.frition]", f"out={tmp_path}/s.json"], tmp_path)
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [r.stderr.strip()], r.stderr
    assert "params=sim.cover.frition" in r.stderr and not (tmp_path / "s.json").exists()


def test_morris_effect_is_the_change_per_bracket():
    from SALib.sample import morris

    prob = {"num_vars": 2, "names": ["a", "b"], "bounds": [[0.6, 1.5], [0.0, 10.0]]}
    X = morris.sample(prob, 4, num_levels=4, seed=0)
    res = sens.analyse(prob, X, {"y": list(3.0 * X[:, 0])}, 4, 0)["y"]
    assert res["mu_star"]["a"] == pytest.approx(3.0 * 0.9)  # slope x bracket width
    assert res["mu_star"]["b"] == pytest.approx(0.0)


def test_tiny_screen_moves_only_what_the_parameter_reaches(tmp_path):
    # through the command line (a subprocess: under pytest `protocols` can name the tests' package)
    from tests.protocols.conftest import run_cli

    key = "sim.rig.gripper.support_stiffness_n_per_mm"
    out = tmp_path / "s.json"
    r = run_cli("protocols.sensitivity", ["size=tiny", "trajectories=2", f"params=[{key}]", f"out={out}"],
                tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(out.read_text())
    m = res["morris"]
    # The gripper's support is in series with the skin on the grip rig only: it moves the grip preload
    # (softer support, less preload) and nothing the platform campaign measures.
    assert m["grip_preload_n"]["mu_star"][key] > 1.0
    assert m["shift_per_n_mm"]["mu_star"][key] == pytest.approx(0.0, abs=1e-9)
    assert m["slide_max_shear_n"]["mu_star"][key] == pytest.approx(0.0, abs=1e-9)
    table = sens.markdown_table(res)
    assert "grip preload" in table and "support_stiffness_n_per_mm" in table
    assert "grip preload" in r.stdout  # the table is printed
