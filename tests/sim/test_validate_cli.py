"""The validation command (a Hydra app through layerskin_exp.cli.run_command): sim.* overrides
reach the checks, a failing check exits 1, a bad override is refused with exit 2 before any check."""

from __future__ import annotations

import sys

import pytest

from layerskin_exp.sim import validate


def _run(monkeypatch, *argv: str) -> None:
    monkeypatch.setattr(sys, "argv", ["validate", *argv])
    validate.cli()


@pytest.mark.parametrize("code", [0, 1])
def test_overrides_reach_the_checks_and_a_failure_exits_1(code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    seen = []
    monkeypatch.setattr(validate, "report", lambda sim: seen.append(sim) or code)
    if code:
        with pytest.raises(SystemExit) as e:
            _run(monkeypatch, "sim.spacer.modulus_kpa=20")
        assert e.value.code == 1
    else:
        _run(monkeypatch, "sim.spacer.modulus_kpa=20")
    assert [s.spacer.modulus_kpa for s in seen] == [20]
    assert list(tmp_path.iterdir()) == []  # no Hydra folders or logs


@pytest.mark.parametrize("arg", ["sim.spacer.modulus_kpa=-1", "sim.spacer.modulus_kpa=abc", "spacer.modulus_kpa=20"])
def test_bad_overrides_are_refused_before_any_check(arg, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(validate, "report", lambda sim: pytest.fail("ran the checks despite a bad override"))
    with pytest.raises(SystemExit) as e:
        _run(monkeypatch, arg)
    assert e.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_the_mid_plane_reading_is_printed_only_where_the_3d_data_carry_it():
    fem = {"superficial_cop_counts_mm": 1.39, "superficial_cop_counts_mid_plane_mm": 1.95,
           "interlayer_shift_counts_mm": -0.31, "interlayer_shift_counts_mid_plane_mm": 0.25,
           "superficial_mid_plane_balance": 0.92}
    fast = {"superficial_cop_counts_mm": 1.04, "interlayer_shift_counts_mm": -0.44}
    old = {k: v for k, v in fem.items() if "mid_plane" not in k}
    lines = validate._mid_plane_lines({"0.83 N": {"3d": fem, "fast": fast}, "3 N": {"3d": old, "fast": fast},
                                       "stiff": {"3d": fem, "fast": None, "error": "did not reach"}})
    assert lines == [
        "3D: superficial_cop_counts_mm at 0.83 N: mid-plane 1.95 (carries 1.92 F_z), faces' mean 1.39, fast 1.04",
        "3D: interlayer_shift_counts_mm at 0.83 N: mid-plane 0.25 (carries 1.92 F_z), faces' mean -0.31, fast -0.44"]
