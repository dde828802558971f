"""Naive per-taxel frame pipeline of the simulated skin: the baseline for `SkinModel.frames`.

`naive_frames(model, states, t_s)` computes the same physics as `SkinModel.frames` the way one
would first write it: frame by frame, taxel by taxel, quadrature point by quadrature point in
plain Python (scalar table interpolation, tilt, lattice factor), then the FSR memories per
taxel, and the passive matrix solved as a full 32-node system once per driven row. Hemisphere
only (the rig's press/slide benchmark). Its noise draws differ from the vectorised path.

`previous_model_class()` is the previous vectorised pipeline (full quadrature grid per frame),
kept as the reference for the fast path's equivalence tests and as the "before" figure.

`run()` times the fast pipeline against the previous one on a hemisphere press-and-slide and a
rod press-and-twist (frames in batches of 32, as the world sends them), the tracemalloc peak of
producing 60 s of frames, and the naive per-taxel pipeline on a few frames.
"""

from __future__ import annotations

import math
import time
import tracemalloc

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



# --------------------------------------------------------------------------------------------
# The previous vectorised pipeline (full 48x48 quadrature grid for every frame, one FSR layer
# and one crosstalk solve at a time), kept verbatim as the reference that the fast
# `SkinModel.frames` must reproduce and as the "before" figure of `run()`.


def _previous_fsr_advance(layer, pressure_kpa, dt_s):
    w, c = layer.cfg.hysteresis, layer.cfg.creep
    alpha = 1.0 - np.exp(-np.maximum(dt_s, 0.0) / layer.cfg.creep_s)
    out = np.empty_like(pressure_kpa)
    play, lag = layer.play, layer.lag
    for k in range(pressure_kpa.shape[0]):
        p = np.maximum(pressure_kpa[k], 0.0)
        play = np.clip(play, p * (1.0 - w), p * (1.0 + w))
        lag = lag + alpha[k] * (play - lag)
        out[k] = (1.0 - c) * play + c * lag
    layer.play, layer.lag = play, lag
    return out


def _previous_conductance_s(layer, pressure_kpa):
    x = (np.maximum(pressure_kpa, 0.0) / layer.cfg.saturation_kpa) ** layer.cfg.exponent
    return layer.gain * (layer.g_floor_s + layer.g_sat_s * x / (1.0 + x))


def _previous_column_volts(ro, g_s):
    vs = ro.cfg.supply_v
    if not ro.cfg.crosstalk:
        r_div = 1.0 / ro.g_div
        return vs * r_div / (ro.r_on + 1.0 / g_s + r_div)
    d_r = g_s.sum(axis=2) + ro.g_leak
    d_c = g_s.sum(axis=1) + ro.g_div
    g_over = g_s / d_c[:, None, :]
    s_mat = -g_over @ np.swapaxes(g_s, 1, 2)
    idx = np.arange(ro.n)
    s_mat[:, idx, idx] += d_r
    z_rr = np.linalg.inv(s_mat)
    z_rc = z_rr @ g_over
    z_ii = z_rr[:, idx, idx][:, :, None]
    if ro.r_on > 0:
        g_on = 1.0 / ro.r_on
        return vs * g_on * z_rc / (1.0 + g_on * z_ii)
    return vs * z_rc / z_ii


def previous_model_class():
    """The previous `SkinModel` frame pipeline as a subclass (imported lazily: sim is heavy)."""
    from layerskin_exp.sim.skin import MechState, SkinModel, StateBatch, _chord, stack_states
    from layerskin_exp.sim.spacer import hex_cell_pattern

    class PreviousSkinModel(SkinModel):
        """Same mechanics (`step`) and random draws; the previous pressure/frame pipeline."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            sim, skin = self.sim, self.skin
            g, w = np.polynomial.legendre.leggauss(sim.contact.quad_points)
            centres = skin.taxel_centres_mm()
            self._pv_q = (centres[:, None] + 0.5 * skin.electrode_mm * g[None, :]).ravel()
            self._pv_qw = 0.5 * w
            self._pv_nq = sim.contact.quad_points
            qx, qy = np.meshgrid(self._pv_q, self._pv_q)
            self._pv_lattice32 = hex_cell_pattern(qx, qy, sim.spacer.cell, sim.spacer.lattice_contrast).astype(np.float32)
            self._pv_build_lookups()
            self._pv_last_maps = None
            self._pv_last_t = None

        def _pv_build_lookups(self) -> None:
            """Resample the profile tables for nearest-bin lookups: in r^2 (hemisphere, no sqrt per
            point) or in the signed distance (rod), on a grid fine enough that nearest-bin error is
            far below the profile's own scale (float32, flattened with one guard column of zeros)."""
            tab = self.tab
            if self.kind == "hemisphere":
                r2_max = float(tab.dist_mm[-1]) ** 2
                step = 0.01  # mm^2
                grid = np.arange(0.0, r2_max, step)
                at = np.sqrt(grid)
                self._pv_lk_origin, self._pv_lk_scale = 0.0, 1.0 / step
            else:
                step = 0.005  # mm
                grid = np.arange(tab.dist_mm[0], tab.dist_mm[-1], step)
                at = grid
                self._pv_lk_origin, self._pv_lk_scale = float(tab.dist_mm[0]), 1.0 / step
            self._pv_lk_n = len(grid) + 1

            def resample(table):
                out = np.zeros((table.shape[0], self._pv_lk_n), dtype=np.float32)
                for k in range(table.shape[0]):
                    out[k, :-1] = np.interp(at, tab.dist_mm, table[k])
                return out.ravel()

            self._pv_lk_sup = resample(tab.superficial_kpa)
            self._pv_lk_deep = resample(tab.deep_kpa)

        def _pv_delta_index(self, delta: np.ndarray):
            x = np.clip(delta / self.tab.d_delta, 0.0, len(self.tab.delta_mm) - 1.000001)
            i = x.astype(np.int64)
            return i, (x - i)

        def _pv_lookup_profile(self, flat: np.ndarray, i: np.ndarray, t: np.ndarray, coord: np.ndarray) -> np.ndarray:
            """Profile value at coord (N, ...) (r^2 or signed distance) for frames with delta row i + t."""
            n = self._pv_lk_n
            j = ((coord - self._pv_lk_origin) * self._pv_lk_scale + 0.5).astype(np.int64)
            np.clip(j, 0, n - 1, out=j)
            np.putmask(j, j >= n - 1, n - 1)  # guard column: zero outside the table
            shape = (-1,) + (1,) * (coord.ndim - 1)
            idx = j + (i * n).reshape(shape)
            tt = t.astype(np.float32).reshape(shape)
            lo = flat.take(idx)
            return lo + (flat.take(idx + n) - lo) * tt

        def _pv_tilt(self, i: np.ndarray, t: np.ndarray, shift: np.ndarray):
            """Exponential-tilt rate and log-normaliser giving a deep-CoP shift (mm) at each frame."""
            tab = self.tab
            ds = tab.tilt_shift_mm[1] - tab.tilt_shift_mm[0]
            x = np.clip(shift / ds, 0.0, len(tab.tilt_shift_mm) - 1.000001)
            si = x.astype(np.int64)
            su = x - si

            def bilerp(table):
                a = table[i, si] * (1 - su) + table[i, si + 1] * su
                b = table[i + 1, si] * (1 - su) + table[i + 1, si + 1] * su
                return a * (1 - t) + b * t

            return bilerp(tab.tilt_gamma), bilerp(tab.tilt_logz)

        def _pv_taxel_mean(self, field: np.ndarray) -> np.ndarray:
            n, q = self.skin.n_taxels, self._pv_nq
            f = field.reshape(field.shape[0], n, q, n, q)
            w = self._pv_qw.astype(np.float32)
            return np.einsum("aiqjr,q,r->aij", f, w, w, optimize=True).astype(float)

        def pressure_fields(self, batch: StateBatch) -> tuple[np.ndarray, np.ndarray]:
            """Pressure (kPa, float32) at the quadrature points (N, n*q, n*q) of both layers, [y, x]."""
            delta = batch.indentation_mm
            fz = batch.force_n[:, 2]
            ft = batch.force_n[:, :2]
            a = batch.contact_xy_mm
            cd = a + batch.surface_shift_mm  # contact in the deep frame
            q = self._pv_q.astype(np.float32)
            h_eff = self.stack_height_mm(delta)
            ft_mag = np.hypot(ft[:, 0], ft[:, 1])
            with np.errstate(invalid="ignore", divide="ignore"):
                shift = np.where(fz > 0, ft_mag * h_eff / fz, 0.0)  # moment balance: F_t H = F_z shift
            i, t = self._pv_delta_index(delta)
            gamma, logz = self._pv_tilt(i, t, shift)
            f32 = np.float32
            dxs = q[None, :] - a[:, 0:1].astype(f32)  # superficial-frame offsets (N, nq)
            dys = q[None, :] - a[:, 1:2].astype(f32)
            dxd = q[None, :] - cd[:, 0:1].astype(f32)  # deep-frame offsets
            dyd = q[None, :] - cd[:, 1:2].astype(f32)
            if self.kind == "hemisphere":
                sup = self._pv_lookup_profile(self._pv_lk_sup, i, t, dxs[:, None, :] ** 2 + dys[:, :, None] ** 2)
                with np.errstate(invalid="ignore", divide="ignore"):
                    nrm = np.where(ft_mag[:, None] > 0, ft / ft_mag[:, None], 0.0).astype(f32)
                g = (gamma[:, None] * nrm).astype(f32)  # tilt along the shear direction
                tilt = np.exp((g[:, 0, None] * dxd - 0.5 * logz[:, None].astype(f32))[:, None, :]
                              + (g[:, 1, None] * dyd - 0.5 * logz[:, None].astype(f32))[:, :, None])
                deep = self._pv_lookup_profile(self._pv_lk_deep, i, t, dxd[:, None, :] ** 2 + dyd[:, :, None] ** 2) * tilt
            else:
                sup, deep = self._pv_rod_fields(batch, i, t, gamma, logz, h_eff, dxs, dys, dxd, dyd)
            live = (fz > 0).astype(f32)[:, None, None]
            return sup * live, deep * self._pv_lattice32[None] * live

        def _pv_rod_fields(self, batch, i, t, gamma, logz, h_eff, dxs, dys, dxd, dyd):
            f32 = np.float32
            yaw = batch.indenter_yaw_rad
            yaw_s = yaw - batch.surface_rotation_rad  # rod axis in the superficial frame
            ps = (-np.sin(yaw_s)).astype(f32)[:, None, None] * dxs[:, None, :] + np.cos(yaw_s).astype(f32)[:, None, None] * dys[:, :, None]
            sup = self._pv_lookup_profile(self._pv_lk_sup, i, t, ps)
            fz = batch.force_n[:, 2]
            cd = batch.contact_xy_mm + batch.surface_shift_mm
            chords = np.array([_chord(float(c[0]), float(c[1]), float(w), self._half) for c, w in zip(cd, yaw, strict=True)])
            length = np.maximum(chords[:, 1] - chords[:, 0], 1e-9)
            line_q = fz / length  # N/mm
            i_s = (chords[:, 1] ** 3 - chords[:, 0] ** 3) / 3.0
            with np.errstate(invalid="ignore", divide="ignore"):
                # torsion: traction T s / I_s across the line; its moment shifts the deep line by T H s / (I_s q)
                twist = np.where(fz > 0, np.arctan(batch.torque_z_nmm * h_eff / (i_s * line_q)), 0.0)
            yaw_d = yaw + twist
            ex, ey = np.cos(yaw_d).astype(f32), np.sin(yaw_d).astype(f32)
            along = ex[:, None, None] * dxd[:, None, :] + ey[:, None, None] * dyd[:, :, None]
            perp = -ey[:, None, None] * dxd[:, None, :] + ex[:, None, None] * dyd[:, :, None]
            ft = batch.force_n[:, :2]
            f_perp = -ft[:, 0] * ey + ft[:, 1] * ex
            f_along = ft[:, 0] * ex + ft[:, 1] * ey
            g = (np.sign(f_perp) * gamma).astype(f32)[:, None, None]
            deep = self._pv_lookup_profile(self._pv_lk_deep, i, t, perp) * np.exp(g * perp - logz.astype(f32)[:, None, None])
            # along-axis shear: its moment is balanced by a linear load gradient along the line
            mid = 0.5 * (chords[:, 0] + chords[:, 1])
            with np.errstate(invalid="ignore", divide="ignore"):
                beta = np.where(fz > 0, f_along * h_eff / (line_q * length**3 / 12.0), 0.0)
            ramp = 1.0 + beta.astype(f32)[:, None, None] * (along - mid.astype(f32)[:, None, None])
            return sup, deep * np.maximum(ramp, 0.0)

        def pressure_maps(self, states: list[MechState]) -> tuple[np.ndarray, np.ndarray]:
            """(N, 16, 16) mean pressure (kPa) over each taxel's electrode: superficial, deep."""
            sup, deep = self.pressure_fields(stack_states(states))
            return self._pv_taxel_mean(sup), self._pv_taxel_mean(deep)

        # ------------------------------------------------------------------ frames
        def _pv_row_times(self, t_s: np.ndarray) -> np.ndarray:
            """(N, 2, n) sampling instants: t_s[k] ends the frame; rows sampled in sequence before it."""
            n = self.skin.n_taxels
            period = self.skin.frame_period_ms * 1e-3
            slot = np.arange(2 * n).reshape(2, n)
            t = t_s[:, None, None] - (2 * n - 1 - slot)[None] * period / (2 * n)
            jit = self.sim.readout.scan_jitter_ms * 1e-3
            if jit > 0:
                t = t + self.rng.normal(0.0, jit, size=t.shape)
            return t

        def frames(self, states: list[MechState], t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """(superficial, deep) uint16 counts (N, 16, 16) for frames completed at t_s (N,)."""
            t_s = np.asarray(t_s, dtype=float).reshape(-1)
            if len(states) != len(t_s):
                raise ValueError(f"frames: {len(states)} states for {len(t_s)} frame times; pass one state per frame")
            sup, deep = self.pressure_maps(states)
            maps = np.stack([sup, deep], axis=1)  # (N, 2, n, n)
            prev_maps = np.concatenate([maps[:1] if self._pv_last_maps is None else self._pv_last_maps[None], maps[:-1]])
            prev_t = np.concatenate([[t_s[0] - self.skin.frame_period_ms * 1e-3 if self._pv_last_t is None
                                      else self._pv_last_t], t_s[:-1]])
            span = np.maximum(t_s - prev_t, 1e-9)
            rows_t = self._pv_row_times(t_s)
            w_prev = np.clip((t_s[:, None, None] - rows_t) / span[:, None, None], 0.0, 1.0)[..., None]
            sampled = maps * (1 - w_prev) + prev_maps * w_prev  # each row at its own instant
            self._pv_last_maps, self._pv_last_t = maps[-1], float(t_s[-1])
            dt = np.diff(np.concatenate([[prev_t[0]], t_s]))
            counts = []
            for layer in range(2):
                eff = _previous_fsr_advance(self.fsr[layer], sampled[:, layer], dt)
                g = _previous_conductance_s(self.fsr[layer], eff)
                c = self.readout.counts(_previous_column_volts(self.readout, g)) + self.baseline_counts[layer]
                counts.append(c)
            out = np.stack(counts, axis=0)
            noise = self.sim.readout.noise_counts
            if noise > 0:
                out = out + self.rng.normal(0.0, noise, size=out.shape)
            out = np.clip(np.rint(out), 0, self.readout.full_scale).astype(np.uint16)
            return out[0], out[1]


    return PreviousSkinModel


def _press_and_slide(model, n_steps=1000):
    states = []
    for k in range(n_steps):
        z = -2.2 * min(k / 300.0, 1.0)
        x = 0.004 * max(k - 300, 0)
        states.append(model.step(k * 1e-3, np.array([x, 0.0, z])))
    return states


def _rod_twist(model, n_steps=1000):
    """Rod across the pad pressed through the gripper's series compliance, then twisted 25 deg."""
    states = []
    for k in range(n_steps):
        z = -2.3 * min(k / 300.0, 1.0)
        yaw = math.pi / 2 + math.radians(25.0) * max(k - 300, 0) / 700.0
        states.append(model.step(k * 1e-3, np.array([0.5, 0.0, z]), yaw))
    return states


def _frame_cost_us(model, states, repeats=3):
    """Best-of-repeats wall time per frame pair, ~424 frames per simulated second, batches of 32."""
    picked = states[::2][:424]
    t = np.array([s.t_s for s in picked])
    best = math.inf
    for r in range(repeats):
        t0 = time.perf_counter()
        for lo in range(0, len(picked), 32):  # batches as the world sends them
            model.frames(picked[lo:lo + 32], t[lo:lo + 32] + r * 10.0)
        best = min(best, (time.perf_counter() - t0) / len(picked) * 1e6)
    return best


def _trial_peak_mb(model, states, seconds=60.0):
    """tracemalloc peak (MB) while producing `seconds` of frames (424 Hz, batches of 32), kept."""
    picked = states[::2][:424]
    n = int(seconds * 424)
    kept = []
    tracemalloc.start()
    for lo in range(0, n, 32):
        idx = np.arange(lo, min(lo + 32, n))
        kept.append(model.frames([picked[i % len(picked)] for i in idx], idx * 2.36e-3 + 100.0))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 1e6


def run() -> dict:
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.config import SimConfig
    from layerskin_exp.sim.skin import SkinModel

    sim, skin = SimConfig(), SkinConfig()
    previous = previous_model_class()
    out = {}
    for kind, drive in (("hemisphere", _press_and_slide), ("rod", _rod_twist)):
        fast = SkinModel(sim, skin, kind, np.random.default_rng(0))
        t0 = time.perf_counter()
        states = drive(fast)
        step_us = (time.perf_counter() - t0) / len(states) * 1e6
        ref = previous(sim, skin, kind, np.random.default_rng(0))
        frame_us = _frame_cost_us(fast, states)
        prev_us = _frame_cost_us(ref, states)
        out[f"{kind}_step_us"] = step_us
        out[f"{kind}_frames_us_per_frame_pair"] = frame_us
        out[f"{kind}_baseline_previous_us_per_frame_pair"] = prev_us
        out[f"{kind}_speedup_vs_previous"] = prev_us / frame_us
        # one simulated second: ~1000 mechanics steps and ~424 frame pairs
        out[f"{kind}_x_realtime"] = 1.0 / (1000 * step_us * 1e-6 + 424 * frame_us * 1e-6)
        out[f"{kind}_baseline_previous_x_realtime"] = 1.0 / (1000 * step_us * 1e-6 + 424 * prev_us * 1e-6)
        if kind == "hemisphere":
            out["frames_60s_peak_mb"] = _trial_peak_mb(SkinModel(sim, skin, kind, np.random.default_rng(0)), states)
            out["baseline_previous_frames_60s_peak_mb"] = _trial_peak_mb(
                previous(sim, skin, kind, np.random.default_rng(0)), states)
            slow = SkinModel(sim, skin, kind, np.random.default_rng(0))
            few = _press_and_slide(slow)[::2][300:306]
            t0 = time.perf_counter()
            naive_frames(slow, few, np.array([s.t_s for s in few]))
            naive_us = (time.perf_counter() - t0) / len(few) * 1e6
            out["baseline_naive_us_per_frame_pair"] = naive_us
            out["speedup_vs_naive"] = naive_us / frame_us
    return out


if __name__ == "__main__":
    print(run())
