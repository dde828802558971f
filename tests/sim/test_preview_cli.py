"""The preview command: --help writes nothing; sim.* overrides reach the model; bad ones are refused."""

from __future__ import annotations

import pytest

from layerskin_exp.sim import preview


def test_help_writes_no_png(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    preview.main(["--help"])
    assert "sim.KEY=VALUE" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


def test_sim_overrides_reach_the_model(tmp_path, monkeypatch):
    seen = {}
    monkeypatch.setattr(preview, "render", lambda out, sim, skin: seen.update(out=out, sim=sim, skin=skin) or out)
    preview.main([f"out={tmp_path / 'p.png'}", "sim.spacer.modulus_kpa=20", "seed=4", "skin.frame_period_ms=2.5"])
    assert seen["sim"].spacer.modulus_kpa == 20 and seen["sim"].seed == 4 and seen["skin"].frame_period_ms == 2.5


@pytest.mark.parametrize("arg", ["sim.spacer.modulus_kpa=-1", "sim.no_such_key=1", "bogus", "skin.pitch_mm=1.4"])
def test_bad_arguments_are_refused(arg, monkeypatch):
    monkeypatch.setattr(preview, "render", lambda *a, **k: pytest.fail("rendered despite a bad argument"))
    with pytest.raises(SystemExit) as e:
        preview.main([arg])
    assert e.value.code == 2
