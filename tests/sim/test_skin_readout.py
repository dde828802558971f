"""Transduction and readout of the simulated skin: FSR law, crosstalk, determinism, config."""

from __future__ import annotations

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from layerskin_exp.config import ConfigError, SkinConfig, validate
from layerskin_exp.sim.config import CoverConfig, FSRConfig, ReadoutConfig, SimConfig, SpacerConfig
from layerskin_exp.sim.fsr import FSRLayer
from layerskin_exp.sim.readout import MatrixReadout
from layerskin_exp.sim.skin import SkinModel

SKIN = SkinConfig()
CONF_DIR = str(__import__("pathlib").Path(__file__).resolve().parents[2] / "conf")


def test_transduction_is_monotone_and_saturating():
    fsr = FSRLayer(FSRConfig(gain_cv=0.0), (16, 16), np.random.default_rng(0))
    ro = MatrixReadout(ReadoutConfig(crosstalk=False), 12)
    p = np.geomspace(1.0, 5000.0, 60)
    field = np.zeros((60, 16, 16))
    field[:, 3, 4] = p
    counts = ro.counts(ro.column_volts(fsr.conductance_s(field)))[:, 3, 4]
    assert np.all(np.diff(counts) > 0)
    assert counts[-1] < 4095
    # saturation: the count gained per kPa falls by orders of magnitude
    slope = np.diff(counts) / np.diff(p)
    assert slope[-1] < 0.01 * slope.max()
    # closed form for an isolated taxel: divider with the saturated conductance in series
    g_sat = 1 / 1e3
    v_top = 3.3 * 10e3 / (70 + 1 / (g_sat + 1 / 5e6) + 10e3)
    assert ro.counts(np.array(v_top)) > counts[-1]


def test_hysteresis_reads_higher_on_unloading_and_creep_settles():
    cfg = FSRConfig(gain_cv=0.0, creep=0.0)
    fsr = FSRLayer(cfg, (16, 16), np.random.default_rng(0))
    up = np.linspace(0, 100, 50)
    path = np.concatenate([up, up[::-1]])
    eff = fsr.advance(np.broadcast_to(path[:, None, None], (100, 16, 16)).copy(), np.full(100, 0.01))[:, 0, 0]
    k = 25  # same pressure on the way up and down
    assert eff[99 - k] > path[99 - k] > eff[k] - 1e-12
    creep = FSRLayer(FSRConfig(gain_cv=0.0, hysteresis=0.0, creep=0.1, creep_s=1.0), (16, 16), np.random.default_rng(0))
    held = creep.advance(np.full((400, 16, 16), 50.0), np.full(400, 0.01))[:, 0, 0]
    assert np.all(np.diff(held) >= 0) and held[0] == pytest.approx(45.0, rel=0.01)
    assert held[-1] == pytest.approx(50.0 - 5.0 * np.exp(-4.0), rel=1e-3)


def _nodal_reference(g, ro):
    """Full 32-node solve, one driven row at a time (independent of the block elimination)."""
    n = 16
    out = np.zeros((n, n))
    for i in range(n):
        y = np.zeros((2 * n, 2 * n))
        y[:n, :n] = np.diag(g.sum(axis=1) + ro.g_leak)
        y[n:, n:] = np.diag(g.sum(axis=0) + ro.g_div)
        y[:n, n:], y[n:, :n] = -g, -g.T
        rhs = np.zeros(2 * n)
        y[i, i] += 1 / ro.r_on
        rhs[i] = ro.cfg.supply_v / ro.r_on
        out[i] = np.linalg.solve(y, rhs)[n:]
    return out


def test_crosstalk_ghost_at_fourth_corner_and_none_without():
    g = np.full((16, 16), 1 / 5e6)
    for r, c in ((2, 3), (2, 11), (9, 3)):  # three corners of a rectangle
        g[r, c] = 1 / 1.5e3
    on = MatrixReadout(ReadoutConfig(crosstalk=True), 12)
    off = MatrixReadout(ReadoutConfig(crosstalk=False), 12)
    v_on, v_off = on.column_volts(g[None])[0], off.column_volts(g[None])[0]
    np.testing.assert_allclose(v_on, _nodal_reference(g, on), rtol=1e-9, atol=1e-12)
    ghost, elsewhere = on.counts(v_on[9, 11]), on.counts(v_on[12, 6])
    assert ghost > 100 and ghost > 20 * max(elsewhere, 1.0)
    assert off.counts(v_off[9, 11]) == pytest.approx(off.counts(v_off[12, 6]))
    assert off.counts(v_off[9, 11]) == pytest.approx(4095 * 10e3 / (70 + 5e6 + 10e3), rel=1e-9)


def _run(seed, crosstalk=True):
    sim = SimConfig(seed=seed, readout=ReadoutConfig(crosstalk=crosstalk))
    m = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(seed))
    states = [m.step(k * 1e-3, np.array([0.002 * k, 0.0, -2.2 * min(k / 100, 1.0)])) for k in range(400)]
    pick = states[::10]
    t = np.array([s.t_s for s in pick]) + 1e-4
    return m.frames(pick[:20], t[:20]) + m.frames(pick[20:], t[20:])


def test_frames_are_deterministic_under_a_seed_and_well_formed():
    a, b, c = _run(3), _run(3), _run(4)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert any(not np.array_equal(x, y) for x, y in zip(a, c, strict=True))
    sup = np.concatenate([a[0], a[2]])
    assert sup.dtype == np.uint16 and sup.shape == (40, 16, 16) and sup.max() <= 4095
    assert sup[-1].max() > 1000  # pressed at the end


@pytest.mark.parametrize("factory,key", [
    (lambda: SpacerConfig(modulus_kpa=0.0), "sim.spacer.modulus_kpa"),
    (lambda: SpacerConfig(thickness_mm=-1.0), "sim.spacer.thickness_mm"),
    (lambda: SpacerConfig(cell_mm=0.0), "sim.spacer.cell_mm"),
    (lambda: CoverConfig(thickness_mm=0.0), "sim.cover.thickness_mm"),
    (lambda: CoverConfig(friction=-0.2), "sim.cover.friction"),
    (lambda: FSRConfig(gain_cv=-0.1), "sim.fsr.gain_cv"),
    (lambda: ReadoutConfig(divider_kohm=0.0), "sim.readout.divider_kohm"),
])
def test_config_range_errors_name_the_key(factory, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        factory()


def test_hydra_sweep_key_and_refusal():
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name=None, overrides=["+sim=default", "sim.spacer.modulus_kpa=20", "sim.cover.friction=0.8"])
        sim = validate(cfg, "sim")
        assert sim.spacer.modulus_kpa == 20.0 and sim.cover.friction == 0.8 and sim.spacer.cell_mm == 2.0
        bad = compose(config_name=None, overrides=["+sim=default", "sim.spacer.thickness_mm=0"])
        with pytest.raises(ConfigError, match=r"sim\.spacer\.thickness_mm"):
            validate(bad, "sim")
