"""Naive per-taxel frame pipeline of the simulated skin: the baseline for `SkinModel.frames`.

`naive_frames(model, states, t_s)` computes the same physics as `SkinModel.frames` the way one
would first write it: frame by frame, taxel by taxel, quadrature point by quadrature point in
plain Python (scalar table interpolation, tilt, lattice factor), then the FSR memories per
taxel, and the passive matrix solved as a full 32-node system once per driven row. Hemisphere
only (the rig's press/slide benchmark). Its noise draws differ from the vectorised path.

`run()` times both on a press-and-slide and returns the per-frame costs.
"""

from __future__ import annotations

import math
import time

import numpy as np


def _interp_row(table, d_delta, delta, dist, dist_mm):
    x = min(max(delta / d_delta, 0.0), table.shape[0] - 1.000001)
    i = int(x)
    t = x - i
    a = float(np.interp(dist, dist_mm, table[i], right=0.0))
    b = float(np.interp(dist, dist_mm, table[i + 1], right=0.0))
    return a + (b - a) * t


def naive_frames(model, states, t_s):
    """(superficial, deep) uint16 counts (N, 16, 16), computed one taxel at a time."""
    if model.kind != "hemisphere":
        raise NotImplementedError("naive_frames covers the hemisphere indenter only")
    from layerskin_exp.sim.spacer import hex_cell_pattern

    tab, skin, sim = model.tab, model.skin, model.sim
    n = skin.n_taxels
    g, w = np.polynomial.legendre.leggauss(sim.contact.quad_points)
    centres = skin.taxel_centres_mm()
    period = skin.frame_period_ms * 1e-3
    ro = model.readout
    out = np.zeros((len(states), 2, n, n))
    prev_maps = getattr(model, "_naive_last", None)
    prev_t = t_s[0] - period
    for k, st in enumerate(states):
        delta = st.indentation_mm
        fz = float(st.force_n[2])
        fx, fy = float(st.force_n[0]), float(st.force_n[1])
        ax, ay = float(st.contact_xy_mm[0]), float(st.contact_xy_mm[1])
        cx, cy = ax + float(st.surface_shift_mm[0]), ay + float(st.surface_shift_mm[1])
        h = float(model.stack_height_mm(delta))
        ft = math.hypot(fx, fy)
        shift = ft * h / fz if fz > 0 else 0.0
        x = min(max(delta / tab.d_delta, 0.0), len(tab.delta_mm) - 1.000001)
        i0 = int(x)
        tt = x - i0
        gam = (1 - tt) * np.interp(shift, tab.tilt_shift_mm, tab.tilt_gamma[i0]) + tt * np.interp(
            shift, tab.tilt_shift_mm, tab.tilt_gamma[i0 + 1])
        lz = (1 - tt) * np.interp(shift, tab.tilt_shift_mm, tab.tilt_logz[i0]) + tt * np.interp(
            shift, tab.tilt_shift_mm, tab.tilt_logz[i0 + 1])
        nx, ny = (fx / ft, fy / ft) if ft > 0 else (0.0, 0.0)
        maps = np.zeros((2, n, n))
        for r in range(n):
            for c in range(n):
                ps = pd = 0.0
                for qa, wa in zip(g, w, strict=True):
                    for qb, wb in zip(g, w, strict=True):
                        px = centres[c] + 0.5 * skin.electrode_mm * qb
                        py = centres[r] + 0.5 * skin.electrode_mm * qa
                        wt = 0.25 * wa * wb
                        if fz <= 0:
                            continue
                        ps += wt * _interp_row(tab.superficial_kpa, tab.d_delta, delta, math.hypot(px - ax, py - ay), tab.dist_mm)
                        base = _interp_row(tab.deep_kpa, tab.d_delta, delta, math.hypot(px - cx, py - cy), tab.dist_mm)
                        lat = float(hex_cell_pattern(px, py, sim.spacer.cell, sim.spacer.lattice_contrast))
                        pd += wt * base * math.exp(gam * ((px - cx) * nx + (py - cy) * ny) - lz) * lat
                maps[0, r, c], maps[1, r, c] = ps, pd
        if prev_maps is None:
            prev_maps = maps
        span = max(t_s[k] - prev_t, 1e-9)
        for layer in range(2):
            fsr = model.fsr[layer]
            alpha = 1.0 - math.exp(-max(t_s[k] - prev_t, 0.0) / sim.fsr.creep_s)
            gmat = np.zeros((n, n))
            for r in range(n):
                t_row = t_s[k] - (2 * n - 1 - (layer * n + r)) * period / (2 * n)
                wp = min(max((t_s[k] - t_row) / span, 0.0), 1.0)
                for c in range(n):
                    p = max(maps[layer, r, c] * (1 - wp) + prev_maps[layer, r, c] * wp, 0.0)
                    play = min(max(fsr.play[r, c], p * (1 - sim.fsr.hysteresis)), p * (1 + sim.fsr.hysteresis))
                    lag = fsr.lag[r, c] + alpha * (play - fsr.lag[r, c])
                    fsr.play[r, c], fsr.lag[r, c] = play, lag
                    eff = (1 - sim.fsr.creep) * play + sim.fsr.creep * lag
                    xx = (eff / sim.fsr.saturation_kpa) ** sim.fsr.exponent
                    gmat[r, c] = fsr.gain[r, c] * (fsr.g_floor_s + fsr.g_sat_s * xx / (1 + xx))
            for r in range(n):  # one full nodal solve per driven row
                y = np.zeros((2 * n, 2 * n))
                y[:n, :n] = np.diag(gmat.sum(axis=1) + ro.g_leak)
                y[n:, n:] = np.diag(gmat.sum(axis=0) + ro.g_div)
                y[:n, n:], y[n:, :n] = -gmat, -gmat.T
                rhs = np.zeros(2 * n)
                y[r, r] += 1.0 / ro.r_on
                rhs[r] = sim.readout.supply_v / ro.r_on
                v = np.linalg.solve(y, rhs)[n:]
                for c in range(n):
                    cnt = v[c] / sim.readout.supply_v * ro.full_scale + model.baseline_counts[layer, r, c]
                    cnt += model.rng.normal(0.0, sim.readout.noise_counts)
                    out[k, layer, r, c] = min(max(round(cnt), 0), ro.full_scale)
        prev_maps, prev_t = maps, t_s[k]
    model._naive_last = prev_maps
    return out[:, 0].astype(np.uint16), out[:, 1].astype(np.uint16)


def _press_and_slide(model, n_steps=1000):
    states = []
    for k in range(n_steps):
        z = -2.2 * min(k / 300.0, 1.0)
        x = 0.004 * max(k - 300, 0)
        states.append(model.step(k * 1e-3, np.array([x, 0.0, z])))
    return states


def run() -> dict:
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.config import SimConfig
    from layerskin_exp.sim.skin import SkinModel

    sim, skin = SimConfig(), SkinConfig()
    fast = SkinModel(sim, skin, "hemisphere", np.random.default_rng(0))
    t0 = time.perf_counter()
    states = _press_and_slide(fast)
    step_us = (time.perf_counter() - t0) / len(states) * 1e6
    frame_idx = np.arange(0, len(states), 2)[:424]  # ~424 frames per simulated second
    picked = [states[i] for i in frame_idx]
    t_frames = np.array([s.t_s for s in picked])
    t0 = time.perf_counter()
    for lo in range(0, len(picked), 32):  # batches as the world sends them
        fast.frames(picked[lo:lo + 32], t_frames[lo:lo + 32])
    frame_us = (time.perf_counter() - t0) / len(picked) * 1e6
    slow = SkinModel(sim, skin, "hemisphere", np.random.default_rng(0))
    _press_and_slide(slow)
    few = picked[300:306]
    t0 = time.perf_counter()
    naive_frames(slow, few, t_frames[300:306])
    naive_us = (time.perf_counter() - t0) / len(few) * 1e6
    return {
        "step_us": step_us,
        "frames_us_per_frame_pair": frame_us,
        "baseline_naive_us_per_frame_pair": naive_us,
        "speedup_vs_naive": naive_us / frame_us,
        "sim_seconds_per_wall_second": 1.0 / (1000 * step_us * 1e-6 + 424 * frame_us * 1e-6),
    }


if __name__ == "__main__":
    print(run())
