"""Readable numpy reference of the skin's frame pipeline, what the compiled kernels are tested
against (noise and scan jitter off).

It takes the same contact tables (`contact.ContactTables`) and the same sheet (gains, offsets)
as a `SkinModel`, and computes each frame the plain way: both layers' pressure on the whole
quadrature grid with linear interpolation on the tables' own grid (no windows, no nearest-bin
lookups, float64), taxel means, the FSR memories row by row at each row's sampling instant,
the conductance law, and the passive matrix as the full 32-node nodal system solved once per
driven row. The physics is the one described in `skin`, `contact`, `fsr` and `readout`.
"""

from __future__ import annotations

import math

import numpy as np

from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.frame_kernels import FOLD_STEP_MM
from layerskin_exp.sim.spacer import hex_cell_pattern


def _row_interp(table: np.ndarray, i: int, t: float, coord: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Table row i + t (linear between rows) at coord, linear on the grid dist, 0 beyond it."""
    a = np.interp(coord, dist, table[i], left=0.0, right=0.0)
    b = np.interp(coord, dist, table[i + 1], left=0.0, right=0.0)
    return a + (b - a) * t


class ReferenceSkin:
    """The frame pipeline of `model` (a SkinModel) in plain numpy, with its own FSR memories."""

    def __init__(self, model) -> None:
        sim, skin = model.sim, model.skin
        if sim.readout.noise_counts > 0 or sim.readout.scan_jitter_ms > 0:
            raise ValueError("ReferenceSkin reproduces the noiseless pipeline: set sim.readout.noise_counts=0 "
                             "and sim.readout.scan_jitter_ms=0")
        self.model, self.tab, self.sim, self.skin = model, model.tab, sim, skin
        n, nq = skin.n_taxels, sim.contact.quad_points
        g, w = np.polynomial.legendre.leggauss(nq)
        self.q = (skin.taxel_centres_mm()[:, None] + 0.5 * skin.electrode_mm * g[None, :]).ravel()  # (n*nq,)
        self.qw = 0.5 * w
        self.x, self.y = np.meshgrid(self.q, self.q)  # [y, x]
        self.lattice = hex_cell_pattern(self.x, self.y, sim.spacer.cell_mm, sim.spacer.lattice_contrast)
        self.play = np.zeros((2, n, n))
        self.lag = np.zeros((2, n, n))
        self.last_maps: np.ndarray | None = None
        self.last_t: float | None = None

    # ------------------------------------------------------------------ pressure
    def _row(self, delta: float) -> tuple[int, float]:
        x = min(max(delta / self.tab.d_delta, 0.0), len(self.tab.delta_mm) - 1.000001)
        return int(x), x - int(x)

    def fields(self, rec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pressure (kPa) of both layers on the quadrature grid (n*q, n*q) [y, x] for one state
        (a row of SkinModel.step_many's records): the superficial core half the contact's and
        half the lattice top's (contact.py), the deep layer the lattice's on the deep sheet;
        neither FSR reads tension."""
        if rec[mk.S_FZ] <= 0.0:
            m = len(self.q)
            return np.zeros((m, m)), np.zeros((m, m))
        contact, lattice, top = self.signed_fields(rec, self.x, self.y, self.lattice)
        return np.maximum(0.5 * (contact + top), 0.0), np.maximum(lattice, 0.0)

    def edge_fields(self, rec: np.ndarray, x: np.ndarray, y: np.ndarray, h_lat: float) -> tuple[np.ndarray, np.ndarray]:
        """The lattice's route at points x, y (mm, the pad centred on the array): its pressure on
        the deep sheet and its top's, from the couple per mm along the pad's sides
        (frame_kernels._edge_loads: the shear's F_t h_L, the torque's T h_L)."""
        tab, two_l = self.tab, self.sim.spacer.width_mm
        cx = rec[mk.S_FX] * h_lat / two_l
        cy = rec[mk.S_FY] * h_lat / two_l
        kk = rec[mk.S_TORQUE] * h_lat * (two_l - 2.0 * float(tab.side_inset_mm)) / (two_l**4 / 6.0)
        # couple per mm across the x- and the y-sides, each pair along its own length
        across_x = np.where(np.abs(y) <= 0.5 * two_l, cx - kk * y, 0.0)
        across_y = np.where(np.abs(x) <= 0.5 * two_l, cy + kk * x, 0.0)

        def side(table):
            return (np.interp(x, tab.edge_dist_mm, table, left=0.0, right=0.0) * across_x
                    + np.interp(y, tab.edge_dist_mm, table, left=0.0, right=0.0) * across_y)

        return side(tab.edge_deep_kpa), side(tab.edge_top_kpa)

    def pad_fold(self, field, cx: float, cy: float, reach_mm: float) -> tuple[float, float, float]:
        """(a, b, c) of the pressure a + b x + c y over the pad (kPa, about its centre) that carries
        the force and first moments of what field(x, y) (an axisymmetric profile about (cx, cy))
        puts beyond the pad's sides within reach_mm: the sheet's rigid-body answer on the lattice
        (frame_kernels._pad_fold), summed on cells whose edges lie on the pad's sides."""
        half = 0.5 * self.sim.spacer.width_mm
        if abs(cx) + reach_mm <= half and abs(cy) + reach_mm <= half:
            return 0.0, 0.0, 0.0
        h = half / max(math.ceil(half / FOLD_STEP_MM), 1)
        gx = (np.arange(math.floor((cx - reach_mm) / h), math.ceil((cx + reach_mm) / h)) + 0.5) * h
        gy = (np.arange(math.floor((cy - reach_mm) / h), math.ceil((cy + reach_mm) / h)) + 0.5) * h
        px, py = np.meshgrid(gx, gy)
        beyond = ((np.abs(px) > half) | (np.abs(py) > half)) & (np.hypot(px - cx, py - cy) <= reach_mm)
        v = np.where(beyond, field(px, py), 0.0) * h * h
        two_l = 2.0 * half
        return float(v.sum()) / two_l**2, float((v * px).sum()) / (two_l**4 / 12), float((v * py).sum()) / (two_l**4 / 12)

    def signed_fields(self, rec: np.ndarray, x: np.ndarray, y: np.ndarray,
                      cells: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The contact's pressure on the sheet (kPa, in the sheet's frame, where the superficial
        taxels are), the lattice's pressure on the deep plane and its top's on the sheet (kPa,
        signed: the bonded lattice pulls where the sheet lifts; times `cells`, its cell pattern)
        at points x, y (mm) for one loaded state. The contact's and the lattice top's patterns lie
        about the cap's point in the sheet's frame, the deep plane's about the cap's ground
        position, that point moved by the sheet's travel (frame_kernels.frame_fields)."""
        tab = self.tab
        i, t = self._row(rec[mk.S_DELTA])
        h = tab.height_mm[i] * (1 - t) + tab.height_mm[i + 1] * t
        h_lat = tab.lattice_height_mm[i] * (1 - t) + tab.lattice_height_mm[i + 1] * t
        fz = rec[mk.S_FZ]
        # the couple of the shear about the deep plane: the tables' response carries the cover's
        # lever; the lattice's lies at the pad's sides (frame_kernels.frame_fields)
        mx, my = rec[mk.S_FX] * h, rec[mk.S_FY] * h
        ax, ay = rec[mk.S_CX], rec[mk.S_CY]
        gx, gy = ax + rec[mk.S_UX], ay + rec[mk.S_UY]  # the cap over the deep sheet
        dist = tab.dist_mm
        if self.tab.kind == "hemisphere":
            def layer(profile, couple, cx, cy, px=x, py=y):
                dx, dy = px - cx, py - cy
                r = np.hypot(dx, dy)
                p0 = _row_interp(profile, i, t, r, dist)
                p1 = _row_interp(couple, i, t, r, dist)
                cos_m = np.where(r > 0, (mx * dx + my * dy) / np.maximum(r, 1e-12), 0.0)
                return p0 + cos_m * p1

            half = 0.5 * self.sim.spacer.width_mm
            on_pad = (np.abs(x) <= half) & (np.abs(y) <= half)

            def folded(cx, cy):
                """The lattice's profile about (cx, cy); the stretched sheet's on the pad only, with its
                rigid-body answer to what lay past the sides (frame_kernels._pad_fold)."""
                p = layer(tab.deep_kpa, tab.deep_couple_kpa, cx, cy)
                if not self.sim.sheet.large_deflection:
                    return p
                a, b, c = self.pad_fold(lambda px, py: layer(tab.deep_kpa, tab.deep_couple_kpa, cx, cy, px, py),
                                        cx, cy, float(dist[-1]))
                return np.where(on_pad, p + a + b * x + c * y, 0.0)

            base, top = self.edge_fields(rec, x, y, h_lat)
            deep, under = folded(gx, gy), folded(ax, ay)
            return layer(tab.cover_kpa, tab.cover_couple_kpa, ax, ay), (deep + base) * cells, (under + top) * cells
        # rod: line load across the axis, per unit length (frame_kernels._rod_fields): the contact
        # and the lattice top about the cap's line in the sheet's frame, the deep plane about the
        # cap's line over the deep sheet (its point moved by the sheet's travel, its axis the
        # rod's yaw); the couple grows along the line with the torque
        yaw_s = rec[mk.S_YAW] - rec[mk.S_THETA]
        s1, s2 = mk.chord(ax, ay, yaw_s, self.model._half)
        length = max(s2 - s1, 1e-9)
        line_q = fz / length
        e = np.array([math.cos(yaw_s), math.sin(yaw_s)])
        nrm = np.array([-e[1], e[0]])
        i_s = (s2**3 - s1**3) / 3.0
        f_across = (mx * nrm[0] + my * nrm[1]) / length
        beta = (rec[mk.S_FX] * e[0] + rec[mk.S_FY] * e[1]) * (h - h_lat) / (line_q * length**3 / 12.0)

        def layer(profile, couple_resp, px, py, yaw, ramped):
            ev = np.array([math.cos(yaw), math.sin(yaw)])
            dx, dy = x - px, y - py
            d = -ev[1] * dx + ev[0] * dy
            along = ev[0] * dx + ev[1] * dy
            couple = f_across + rec[mk.S_TORQUE] * h / i_s * along
            p = _row_interp(profile, i, t, d, dist) + couple * _row_interp(couple_resp, i, t, d, dist)
            return p * np.maximum(1.0 + beta * (along - 0.5 * (s1 + s2)), 0.0) if ramped else p

        base, top = self.edge_fields(rec, x, y, h_lat)
        deep = layer(tab.deep_kpa, tab.deep_couple_kpa, gx, gy, rec[mk.S_YAW], True)
        under = layer(tab.deep_kpa, tab.deep_couple_kpa, ax, ay, yaw_s, True)
        return (layer(tab.cover_kpa, tab.cover_couple_kpa, ax, ay, yaw_s, False), (deep + base) * cells,
                (under + top) * cells)

    def maps(self, recs: np.ndarray) -> np.ndarray:
        """(N, 2, n, n) Gauss means of both layers' pressure over each taxel's electrode (kPa)."""
        n, nq = self.skin.n_taxels, len(self.qw)
        wq = np.outer(self.qw, self.qw)
        out = np.zeros((len(recs), 2, n, n))
        for k, rec in enumerate(recs):
            for layer, f in enumerate(self.fields(rec)):
                out[k, layer] = np.einsum("aibj,ij->ab", f.reshape(n, nq, n, nq), wq)
        return out

    # ------------------------------------------------------------------ frames
    def frames(self, recs: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(superficial, deep) uint16 counts (N, 16, 16) for step records recs completed at t_s."""
        sim, skin, model = self.sim, self.skin, self.model
        n = skin.n_taxels
        period = skin.frame_period_ms * 1e-3
        fsr, ro = sim.fsr, sim.readout
        g_sat, g_floor = 1.0 / (fsr.saturated_kohm * 1e3), 1.0 / (fsr.floor_mohm * 1e6)
        g_div, g_leak, r_on = 1.0 / (ro.divider_kohm * 1e3), 1.0 / (ro.leak_mohm * 1e6), ro.mux_on_ohm
        full_scale = 2**skin.adc_bits - 1
        maps = self.maps(recs)
        out = np.zeros((len(recs), 2, n, n), np.uint16)
        for k in range(len(recs)):
            tk = float(t_s[k])
            prev_t = self.last_t if self.last_t is not None else tk - period
            before = self.last_maps if self.last_maps is not None else maps[k]
            span = max(tk - prev_t, 1e-9)
            alpha = 1.0 - math.exp(-max(tk - prev_t, 0.0) / fsr.creep_s)
            for layer in range(2):
                g = np.zeros((n, n))
                for r in range(n):
                    # row r of this layer is sampled before the frame's end by its scan slot
                    row_t = tk - model._row_offsets_s[layer, r]
                    wt = min(max((tk - row_t) / span, 0.0), 1.0)
                    p = np.maximum(maps[k, layer, r] * (1 - wt) + before[layer, r] * wt, 0.0)
                    play = np.clip(self.play[layer, r], p * (1 - fsr.hysteresis), p * (1 + fsr.hysteresis))
                    self.lag[layer, r] += alpha * (play - self.lag[layer, r])
                    self.play[layer, r] = play
                    eff = (1 - fsr.creep) * play + fsr.creep * self.lag[layer, r]
                    x = (eff / fsr.saturation_kpa) ** fsr.exponent
                    g[r] = model._gains[layer, r] * (g_floor + g_sat * x / (1 + x))
                for r in range(n):  # the full nodal system, one solve per driven row
                    if ro.crosstalk:
                        y = np.zeros((2 * n, 2 * n))
                        y[:n, :n] = np.diag(g.sum(axis=1) + g_leak)
                        y[n:, n:] = np.diag(g.sum(axis=0) + g_div)
                        y[:n, n:], y[n:, :n] = -g, -g.T
                        rhs = np.zeros(2 * n)
                        y[r, r] += 1.0 / r_on
                        rhs[r] = ro.supply_v / r_on
                        volts = np.linalg.solve(y, rhs)[n:]
                    else:
                        volts = ro.supply_v / g_div / (r_on + 1.0 / g[r] + 1.0 / g_div)
                    cnt = volts / ro.supply_v * full_scale + model.baseline_counts[layer, r]
                    out[k, layer, r] = np.clip(np.rint(cnt), 0, full_scale)
            self.last_maps, self.last_t = maps[k], tk
        return out[:, 0], out[:, 1]
