"""The compiled frame pipeline (layerskin_exp.sim.frame_kernels) against independent computations:
the naive per-taxel pipeline, numpy quadrature of the kernel's own fields, the full 32-node
readout solve, the FSR recurrence written out, and the array entry point against frames()."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import FSRConfig, ReadoutConfig, SimConfig
from layerskin_exp.sim.fsr import FSRLayer
from layerskin_exp.sim.readout import MatrixReadout
from layerskin_exp.sim.reference import ReferenceSkin
from layerskin_exp.sim.skin import SkinModel, stack_states
from tests.sim.test_skin_readout import _nodal_reference

SKIN = SkinConfig()


def _press_slide(m, n_steps=400, xy=(1.0, -2.0)):
    """Press to 2.2 mm, then slide +x (the shear's couple loads both layers)."""
    return [m.step(k * 1e-3, np.array([xy[0] + 0.004 * max(k - 150, 0), xy[1], -2.2 * min(k / 150, 1.0)]))
            for k in range(n_steps)]


def _rod_twist(m, n_steps=600):
    """Rod pressed across the pad through a compliant support, twisted and slid along its axis."""
    out = []
    for k in range(n_steps):
        yaw = math.pi / 2 + math.radians(20.0) * max(k - 200, 0) / 400
        out.append(m.step(k * 1e-3, np.array([0.6, 0.002 * max(k - 200, 0), -2.3 * min(k / 200, 1.0)]), yaw))
    return out


def test_frames_match_the_reference_pipeline_on_a_slide():
    """Hemisphere press and slide, frames one at a time: the kernel against the numpy reference
    (sim.reference). Without noise and jitter the counts agree to within 2 counts: on the
    contact's steep rim (the indenter's edge through the 0.2 mm cover) the kernel's nearest bin
    in r^2 and the reference's linear interpolation differ by ~0.1 % of the pressure."""
    sim = SimConfig(seed=1, readout=ReadoutConfig(noise_counts=0.0, scan_jitter_ms=0.0))
    fast = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(1))
    ref = ReferenceSkin(fast)
    recs = fast.step_many(np.arange(400) * 1e-3, np.array(
        [[1.0 + 0.004 * max(k - 150, 0), -2.0, -2.2 * min(k / 150, 1.0)] for k in range(400)]), np.zeros(400))
    idx = [100, 150, 250, 300, 399]
    t = recs[idx, 0]
    got = [fast.frames_of_steps(recs[i:i + 1], t[j:j + 1]) for j, i in enumerate(idx)]
    want = [ref.frames(recs[i:i + 1], t[j:j + 1]) for j, i in enumerate(idx)]
    for layer in range(2):
        g = np.concatenate([x[layer] for x in got]).astype(int)
        w = np.concatenate([x[layer] for x in want]).astype(int)
        d = np.abs(g - w)
        assert d.max() <= 2 and np.mean(d > 0) < 0.03
        assert w.max() > 1000  # loaded frames are compared


def test_taxel_maps_are_the_gauss_means_of_the_fields():
    """The kernel accumulates taxel means inside its field loops; numpy's quadrature of the
    fields it returns (pressure_fields) must give the same maps, hemisphere and rod."""
    for kind, drive, k_support in (("hemisphere", _press_slide, None), ("rod", _rod_twist, 20.0)):
        m = SkinModel(SimConfig(seed=2), SKIN, kind, np.random.default_rng(2), support_stiffness_n_per_mm=k_support)
        states = drive(m)[::37]
        sup, deep = m.pressure_fields(stack_states(states))
        q = m.sim.contact.quad_points
        w = 0.5 * np.polynomial.legendre.leggauss(q)[1]
        n = SKIN.n_taxels
        got = m.pressure_maps(states)
        for field, maps in zip((sup, deep), got, strict=True):
            means = np.einsum("kaibj,i,j->kab", field.astype(float).reshape(len(states), n, q, n, q), w, w)
            scale = float(np.abs(means).max())
            assert scale > 50.0
            np.testing.assert_allclose(maps, means, rtol=1e-5, atol=1e-6 * scale)


def test_crosstalk_readout_matches_the_nodal_solve_on_a_loaded_sheet():
    """Random sheet: floor conductances with spread plus a pressed blob and scattered presses."""
    rng = np.random.default_rng(3)
    ro = MatrixReadout(ReadoutConfig(), 12)
    g = np.stack([np.exp(rng.normal(0, 0.3, (16, 16))) / 5e6 for _ in range(3)])
    yy, xx = np.mgrid[0:16, 0:16]
    g[0] += 1e-3 * np.exp(-((xx - 6) ** 2 + (yy - 9) ** 2) / 6.0)
    g[1][rng.random((16, 16)) < 0.2] = 1 / 1.5e3
    got = ro.column_volts(g)
    for k in range(3):
        np.testing.assert_allclose(got[k], _nodal_reference(g[k], ro), rtol=1e-9, atol=1e-13)


def test_fsr_memories_follow_the_recurrence():
    """Play operator then first-order lag, sample by sample, in plain Python."""
    cfg = FSRConfig(hysteresis=0.1, creep=0.2, creep_s=0.05)
    layer = FSRLayer(cfg, (2, 3), np.random.default_rng(0))
    rng = np.random.default_rng(4)
    p = np.abs(rng.normal(50.0, 40.0, (40, 2, 3))) * (rng.random((40, 2, 3)) > 0.2)
    dt = rng.uniform(0.0, 0.01, 40)
    eff = layer.advance(p, dt)
    play, lag = np.zeros((2, 3)), np.zeros((2, 3))
    for k in range(40):
        alpha = 1.0 - math.exp(-dt[k] / cfg.creep_s)
        for idx in np.ndindex(2, 3):
            play[idx] = min(max(play[idx], p[k][idx] * (1 - cfg.hysteresis)), p[k][idx] * (1 + cfg.hysteresis))
            lag[idx] += alpha * (play[idx] - lag[idx])
            assert eff[k][idx] == pytest.approx((1 - cfg.creep) * play[idx] + cfg.creep * lag[idx], rel=1e-12)
    np.testing.assert_allclose(layer.play, play, rtol=1e-12)
    np.testing.assert_allclose(layer.lag, lag, rtol=1e-12)


def test_frames_batch_is_frames_on_arrays():
    """frames_batch(StateBatch, serials, t) gives frames()' counts and leaves the rng where
    frames() leaves it (noise and jitter on), through a press, a hold (serials repeat) and a
    slide, with batches of varying size."""
    sim = SimConfig(seed=5)
    a = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(5))
    b = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(5))
    states_a, states_b = [], []
    for m, out in ((a, states_a), (b, states_b)):
        for k in range(900):
            x = 0.003 * max(k - 600, 0)  # press, hold 300 ms, slide
            out.append(m.step(k * 1e-3, np.array([x, 0.5, -2.2 * min(k / 300, 1.0) + 0.5 * (k < 10)])))
    pick_a, pick_b = states_a[::2], states_b[::2]
    t = np.array([s.t_s for s in pick_a]) + 2e-4
    lo, got, want = 0, [], []
    for size in [4, 1, 7, 4, 32] * 20:
        if lo >= len(pick_a):
            break
        sl = slice(lo, lo + size)
        want.append(np.stack(a.frames(pick_a[sl], t[sl])))
        serial = np.array([s.config_key[1] for s in pick_b[sl]], dtype=np.int64)
        got.append(np.stack(b.frames_batch(stack_states(pick_b[sl]), serial, t[sl])))
        lo += size
    np.testing.assert_array_equal(np.concatenate(got, axis=1), np.concatenate(want, axis=1))
    assert a.rng.random() == b.rng.random()
    assert b.maps_computed < 0.8 * len(pick_b)  # the hold reused its maps
    assert np.concatenate(got, axis=1).max() > 1000
