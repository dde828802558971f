"""The preview command (a Hydra app through layerskin_exp.cli.run_command): --help writes
nothing; out, seed, sim.* and skin.* reach the model; bad ones are refused with exit 2."""

from __future__ import annotations

import sys

import pytest

from layerskin_exp.sim import preview


def _run(monkeypatch, *argv: str) -> None:
    monkeypatch.setattr(sys, "argv", ["preview", *argv])
    preview.cli()


def test_help_writes_no_png(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        _run(monkeypatch, "--help")
    assert e.value.code == 0
    assert "sim.KEY=VALUE" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


def test_sim_overrides_reach_the_model(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    seen = {}
    monkeypatch.setattr(preview, "render", lambda out, sim, skin: seen.update(out=out, sim=sim, skin=skin) or out)
    _run(monkeypatch, f"out={tmp_path / 'p.png'}", "sim.spacer.modulus_kpa=20", "seed=4", "skin.frame_period_ms=2.5")
    assert seen["out"] == str(tmp_path / "p.png")
    assert seen["sim"].spacer.modulus_kpa == 20 and seen["sim"].seed == 4 and seen["skin"].frame_period_ms == 2.5
    assert list(tmp_path.iterdir()) == []  # no Hydra folders or logs beside the PNG (not written here)


@pytest.mark.parametrize("arg", ["sim.spacer.modulus_kpa=-1", "sim.no_such_key=1", "bogus", "skin.pitch_mm=1.4",
                                 "seed=-1"])
def test_bad_arguments_are_refused(arg, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(preview, "render", lambda *a, **k: pytest.fail("rendered despite a bad argument"))
    with pytest.raises(SystemExit) as e:
        _run(monkeypatch, arg)
    assert e.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
