"""Cost of the skin's frame pipeline: the compiled kernels against the plain numpy reference.

`naive_frames(model, states, t_s)` runs `layerskin_exp.sim.reference.ReferenceSkin` (whole
quadrature grid, linear table interpolation, row-by-row FSR memories, one 32-node nodal solve
per driven row) on a noiseless copy of the model's design: the "before" figure of the frame
kernels, and the baseline `sim_speed` extrapolates from. The reference itself lives in the
package, where the kernels' tests use it.

`run()` times both on a hemisphere press-and-slide and a rod press-and-twist.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np


def _noiseless(model):
    from layerskin_exp.sim.skin import SkinModel

    sim = replace(model.sim, readout=replace(model.sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))
    return SkinModel(sim, model.skin, model.kind, np.random.default_rng(0), support_stiffness_n_per_mm=model.k_support)


def naive_frames(model, states, t_s):
    """(superficial, deep) uint16 counts (N, 16, 16) of MechStates by the numpy reference."""
    from layerskin_exp.sim.reference import ReferenceSkin

    ref = ReferenceSkin(_noiseless(model))
    recs = np.array([[s.t_s, *s.force_n, s.torque_z_nmm, s.indentation_mm, *s.contact_xy_mm, s.indenter_yaw_rad,
                      *s.surface_shift_mm, s.surface_rotation_rad, float(s.slipping), *s.slip_mm, s.slip_rad,
                      s.config_key[1]] for s in states])
    return ref.frames(recs, np.asarray(t_s, float))


def _press_and_slide(model, n_steps=1000):
    return model.step_many(np.arange(n_steps) * 1e-3, np.array(
        [[0.5 + 0.004 * max(k - 300, 0), -1.0, -2.0 * min(k / 300, 1.0)] for k in range(n_steps)]), np.zeros(n_steps))


def _rod_twist(model, n_steps=1000):
    yaw = math.pi / 2 + np.radians(20.0) * np.clip((np.arange(n_steps) - 300) / 700, 0, 1)
    return model.step_many(np.arange(n_steps) * 1e-3, np.array(
        [[0.6, 0.0, -2.2 * min(k / 300, 1.0)] for k in range(n_steps)]), yaw)


def run() -> dict:
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.config import SimConfig
    from layerskin_exp.sim.reference import ReferenceSkin
    from layerskin_exp.sim.skin import SkinModel

    out = {}
    for kind, drive, k in (("hemisphere", _press_and_slide, None), ("rod", _rod_twist, 20.0)):
        sim = SimConfig()
        sim = replace(sim, readout=replace(sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))
        model = SkinModel(sim, SkinConfig(), kind, np.random.default_rng(0), support_stiffness_n_per_mm=k)
        recs = drive(model)[::2]
        t = np.arange(len(recs)) * 2.36e-3
        model.frames_of_steps(recs[:1], t[:1])  # kernels loaded
        t0 = time.perf_counter()
        for lo in range(1, len(recs), 32):
            model.frames_of_steps(recs[lo:lo + 32], t[lo:lo + 32])
        fast_s = (time.perf_counter() - t0) / (len(recs) - 1)
        ref = ReferenceSkin(model)
        t0 = time.perf_counter()
        ref.frames(recs[:20], t[:20])
        ref_s = (time.perf_counter() - t0) / 20
        out[f"{kind}_kernel_frame_pair_us"] = fast_s * 1e6
        out[f"{kind}_reference_frame_pair_ms"] = ref_s * 1e3
        out[f"{kind}_speedup"] = ref_s / fast_s
    return out


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key}: {value:.4g}")
