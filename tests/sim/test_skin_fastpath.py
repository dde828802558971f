"""The compiled frame pipeline against the package's numpy reference (`sim.reference`).

`ReferenceSkin` computes the same physics the plain way: both layers on the whole quadrature
grid with linear interpolation on the contact tables' own grid, the FSR memories row by row,
and the full 32-node nodal solve per driven row. It shares the model's sheet (gains, offsets);
with the read noise and scan jitter off the pressure maps must agree to what the kernels'
nearest-bin lookups and windows (below WINDOW_EPS of the profile's peak) change, and the
counts to within a few counts (at the contact's steep rim).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import ReadoutConfig, SimConfig
from layerskin_exp.sim.reference import ReferenceSkin
from layerskin_exp.sim.skin import SkinModel

SKIN = SkinConfig()
PERIOD_S = SKIN.frame_period_ms * 1e-3


def _model(kind, k_support=None, **readout):
    sim = SimConfig(seed=5, readout=ReadoutConfig(noise_counts=0.0, scan_jitter_ms=0.0, **readout))
    return SkinModel(sim, SKIN, kind, np.random.default_rng(5), support_stiffness_n_per_mm=k_support)


def _records(m, states):
    """The step records (SkinModel.step_many's rows) of MechStates."""
    return np.array([[s.t_s, *s.force_n, s.torque_z_nmm, s.indentation_mm, *s.contact_xy_mm, s.indenter_yaw_rad,
                      *s.surface_shift_mm, s.surface_rotation_rad, float(s.slipping), *s.slip_mm, s.slip_rad,
                      s.config_key[1]] for s in states])


def _press(m):
    """Approach from above, press off-centre to 2.3 mm, hold, release."""
    out = []
    for k in range(1400):
        z = 0.5 - 2.8 * min(k / 500.0, 1.0) if k < 1000 else -2.3 + 0.01 * (k - 1000)
        out.append(m.step(k * 1e-3, np.array([2.3, -4.1, z])))
    return out


def _slide(m):
    """Press, then slide diagonally 8 mm (stick-slip), crossing towards the array's edge."""
    out = [m.step(k * 1e-3, np.array([-6.0, 3.0, -2.2 * min(k / 200.0, 1.0)])) for k in range(300)]
    for k in range(4000):
        out.append(m.step(0.3 + k * 1e-3, np.array([-6.0 + 0.004 * k, 3.0 + 0.0022 * k, -2.2])))
    return out


def _rod_torsion(m):
    """Rod across the pad, pressed through a compliant support, twisted 25 deg and back, slid."""
    out = [m.step(k * 1e-3, np.array([0.7, -0.4, -2.3 * min(k / 300.0, 1.0)]), math.pi / 2) for k in range(400)]
    for k in range(3000):
        yaw = math.pi / 2 + math.radians(25.0) * math.sin(math.pi * k / 3000.0)
        out.append(m.step(0.4 + k * 1e-3, np.array([0.7 + 0.001 * k, -0.4, -2.3]), yaw))
    return out


CASES = {"press": ("hemisphere", None, _press), "slide": ("hemisphere", None, _slide),
         "rod_torsion": ("rod", 20.0, _rod_torsion)}


@pytest.mark.parametrize("case", list(CASES))
def test_pressure_maps_match_the_reference(case):
    kind, k_support, drive = CASES[case]
    fast = _model(kind, k_support)
    ref = ReferenceSkin(fast)
    pick = drive(fast)[::37]
    got = np.stack(fast.pressure_maps(pick), axis=1)
    want = ref.maps(_records(fast, pick))
    scale = float(np.abs(want).max())
    # nearest-bin lookups against linear interpolation: up to ~3 % of the local value (measured
    # 2.9 % under a slide at F_t / F_z = 0.8, where the couple drives the deep field to zero over
    # a fraction of a millimetre) in the
    # tail of the contact's rim, plus what the windows leave out
    np.testing.assert_allclose(got, want, rtol=4e-2, atol=2e-4 * scale)
    assert want[:, 1].max() > 50.0  # loaded frames are compared, not just zeros


@pytest.mark.parametrize("case,crosstalk", [("press", True), ("slide", True), ("rod_torsion", True),
                                            ("slide", False)])
def test_frames_match_the_reference(case, crosstalk):
    kind, k_support, drive = CASES[case]
    fast = _model(kind, k_support, crosstalk=crosstalk)
    ref = ReferenceSkin(fast)
    pick = drive(fast)[::23]
    t = np.arange(len(pick)) * PERIOD_S + 1e-4
    sizes = [1, 32, 5, 17]  # batches as the world sends them, including singles
    lo, got, want = 0, [], []
    while lo < len(pick):
        n = sizes[len(got) % len(sizes)]
        got.append(fast.frames(pick[lo:lo + n], t[lo:lo + n]))
        want.append(ref.frames(_records(fast, pick[lo:lo + n]), t[lo:lo + n]))
        lo += n
    for layer in range(2):
        g = np.concatenate([x[layer] for x in got]).astype(int)
        w = np.concatenate([x[layer] for x in want]).astype(int)
        assert g.shape == w.shape == (len(pick), 16, 16)
        assert (np.abs(g - w) <= 3 + 0.03 * w).all()  # as the fields: a few % where a steep rim meets a bin
        assert np.mean(np.abs(g - w) > 1) < 0.02 and np.mean(g != w) < 0.15  # float32 fields: rounding
    assert max(int(x[0].max()) for x in want) > 1000  # loaded frames are compared


def test_frames_with_noise_are_deterministic_and_noise_has_its_rms():
    sim = SimConfig(seed=2)
    runs = []
    for _ in range(2):
        m = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(2))
        idle = [m.step(k * 1e-3, np.array([0.0, 0.0, 1.0])) for k in range(600)][::2]
        t = np.arange(len(idle)) * PERIOD_S
        runs.append(np.concatenate([m.frames(idle[i:i + 32], t[i:i + 32])[0] for i in range(0, len(idle), 32)]))
    np.testing.assert_array_equal(runs[0], runs[1])
    resid = runs[0].astype(float) - runs[0].mean(axis=0)  # unloaded: offsets + noise only
    rms = float(np.sqrt((resid**2).mean() * len(idle) / (len(idle) - 1)))
    # rounding adds 1/12 count^2 to the configured 1.5 count rms
    assert rms == pytest.approx(math.sqrt(sim.readout.noise_counts**2 + 1 / 12), rel=0.05)


class _AlwaysFull(SkinModel):
    """The same model with the idle-sheet shortcut switched off (every frame the full pipeline)."""

    def frames(self, states, t_s):
        self._idle = False
        return super().frames(states, t_s)


def test_idle_sheet_shortcut_is_the_full_pipeline():
    """Unloaded frames before the first contact take a shortcut (constant counts + noise); with
    the read noise and scan jitter on, every count and the rng stream must match the full path,
    through the first press and the release after it (creep memory: no shortcut any more)."""
    sim = SimConfig(seed=4)
    fast = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(4))
    full = _AlwaysFull(sim, SKIN, "hemisphere", np.random.default_rng(4))
    for m in (fast, full):
        m.reseed(np.random.default_rng(11))
    shortcut = []
    inner = fast._idle_frames
    fast._idle_frames = lambda t: shortcut.append(len(t)) or inner(t)
    got, want = [], []
    for k in range(0, 3000, 7):
        z = 0.6 - 0.002 * k if k < 1400 else -2.2 + 0.004 * (k - 1400)
        batch = [fast.step(k * 1e-3 + j * 1e-3, np.array([1.0, -0.5, z])) for j in range(7)]
        batch_full = [full.step(k * 1e-3 + j * 1e-3, np.array([1.0, -0.5, z])) for j in range(7)]
        t = np.array([s.t_s for s in batch]) + 2e-4
        got.append(np.stack(fast.frames(batch, t)))
        want.append(np.stack(full.frames(batch_full, t)))
    np.testing.assert_array_equal(np.concatenate(got, axis=1), np.concatenate(want, axis=1))
    assert sum(shortcut) > 100  # the approach took the shortcut
    assert not fast._idle  # after a press the creep memory stays: no shortcut
    assert np.concatenate(got, axis=1).max() > 1000  # loaded frames are compared too


def _no_maps_reuse(*args, **kwargs):
    """The same model recomputing every frame's pressure maps (no reuse during holds)."""
    m = SkinModel(*args, **kwargs)
    m.reuse_maps = False
    return m


@pytest.mark.parametrize("kind", ["hemisphere", "rod"])
def test_hold_reuses_maps_exactly(kind):
    """While the indenter holds still the loading configuration repeats and the maps are reused:
    counts (noise on) must equal recomputing every frame, through press, hold, slide, hold."""
    sim = SimConfig(seed=6)
    k_support = 20.0 if kind == "rod" else None
    fast = SkinModel(sim, SKIN, kind, np.random.default_rng(6), support_stiffness_n_per_mm=k_support)
    full = _no_maps_reuse(sim, SKIN, kind, np.random.default_rng(6), support_stiffness_n_per_mm=k_support)

    def pose(k):
        if k < 400:  # press
            return [0.5, -0.3, 0.4 - 2.4 * k / 400]
        if k < 900:  # hold
            return [0.5, -0.3, -2.0]
        if k < 1700:  # slide 2 mm (stick-slip)
            return [0.5 + 2.0 * (k - 900) / 800, -0.3, -2.0]
        return [2.5, -0.3, -2.0]  # hold

    got, want = [], []
    for k0 in range(0, 2400, 5):
        for m, out in ((fast, got), (full, want)):
            batch = [m.step((k0 + j) * 1e-3, np.array(pose(k0 + j)), math.pi / 2) for j in range(5)]
            out.append(np.stack(m.frames(batch[::2], np.array([s.t_s for s in batch[::2]]))))
    np.testing.assert_array_equal(np.concatenate(got, axis=1), np.concatenate(want, axis=1))
    total = sum(x.shape[1] for x in got)
    assert full.maps_computed > 0.9 * total  # the reference recomputed every frame (but the idle approach)
    assert fast.maps_computed < 0.8 * full.maps_computed  # the holds reused the maps
    assert np.concatenate(got, axis=1).max() > 500  # loaded frames
