"""The simulated two-layer skin under one rigid indenter: mechanics step and frame pipeline.

Frames. The deep layer is bonded to the support: the skin frame is the deep layer's frame
(origin at the array centre, x along columns, y along rows). The superficial layer rides on the
spacer: it is displaced by `surface_shift_mm` and rotated by `surface_rotation_rad` about the
contact point, so a point x_s of the superficial frame sits at
    x_deep = a + u + R(theta) (x_s - a),  a = contact_xy_mm, u = surface_shift_mm.

Mechanics (`step`, scalar, ~1 kHz). The realised indentation comes from the contact tables and
the series support compliance; the spacer's shear stiffness (rising with compression) loads
the stick-slip friction at the cover, which gives the tangential force and torque.

Pressure maps (`pressure_maps`, vectorised). Superficial: the contact table's profile around
the contact point, in the superficial frame. Deep: the profile spread through the spacer
around the contact's deep-frame position, tilted so that the deep normal pressure balances
the moment of the shear force about the deep plane (F_t H = F_z shift, H the compressed stack
height), times the lattice's cell pattern. For the rod, torsion loads the line with traction
proportional to the distance along it, whose local moments rotate the deep line.
Each taxel integrates its electrode footprint with Gauss points.

Frames (`frames`): row-sequential sampling instants, FSR hysteresis/creep and conductance,
passive-matrix readout with crosstalk, offsets, noise and quantisation.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import ContactTables, build_tables
from layerskin_exp.sim.friction import StickSlip
from layerskin_exp.sim.fsr import FSRLayer, advance_layers, conductance_layers
from layerskin_exp.sim.readout import MatrixReadout
from layerskin_exp.sim.spacer import SpacerLaw, hex_cell_pattern

INDENTERS = ("hemisphere", "rod")
# The hemisphere's fields are evaluated in a window around the contact: outside it each layer's
# profile (times the deep layer's largest tilt factor) is below this fraction of its peak.
WINDOW_EPS = 1e-8
_TINY = np.finfo(float).tiny


@dataclass
class MechState:
    """One mechanical step (see module docstring for the frames). Units in the names."""

    t_s: float
    force_n: np.ndarray  # (3,) Fx, Fy tangential, Fz >= 0 compressive, on the skin, skin frame
    torque_z_nmm: float
    indentation_mm: float
    contact_xy_mm: np.ndarray  # (2,) superficial-layer frame
    indenter_yaw_rad: float  # rod axis direction in the skin frame
    surface_shift_mm: np.ndarray  # (2,)
    surface_rotation_rad: float
    slipping: bool
    slip_mm: np.ndarray  # (2,) cumulative slip of the cover relative to the indenter
    slip_rad: float
    # (model, n): states with the same key have the same loading configuration (indentation,
    # forces, torque, contact, yaw, shear shift and rotation), hence the same pressure maps
    config_key: tuple | None = None


@dataclass
class StateBatch:
    """N mechanical states as arrays (what the vectorised pipeline consumes)."""

    t_s: np.ndarray  # (N,)
    force_n: np.ndarray  # (N, 3)
    torque_z_nmm: np.ndarray  # (N,)
    indentation_mm: np.ndarray  # (N,)
    contact_xy_mm: np.ndarray  # (N, 2)
    indenter_yaw_rad: np.ndarray  # (N,)
    surface_shift_mm: np.ndarray  # (N, 2)
    surface_rotation_rad: np.ndarray  # (N,)


def stack_states(states: list[MechState]) -> StateBatch:
    return StateBatch(
        t_s=np.array([s.t_s for s in states], dtype=float),
        force_n=np.array([s.force_n for s in states], dtype=float).reshape(-1, 3),
        torque_z_nmm=np.array([s.torque_z_nmm for s in states], dtype=float),
        indentation_mm=np.array([s.indentation_mm for s in states], dtype=float),
        contact_xy_mm=np.array([s.contact_xy_mm for s in states], dtype=float).reshape(-1, 2),
        indenter_yaw_rad=np.array([s.indenter_yaw_rad for s in states], dtype=float),
        surface_shift_mm=np.array([s.surface_shift_mm for s in states], dtype=float).reshape(-1, 2),
        surface_rotation_rad=np.array([s.surface_rotation_rad for s in states], dtype=float),
    )


_TABLE_CACHE: dict[str, ContactTables] = {}
_MODEL_IDS = itertools.count()


def tables_for(sim: SimConfig, kind: str) -> ContactTables:
    """Contact tables for a design, computed once per distinct (spacer, cover, contact) config."""
    key = repr((sim.spacer, sim.cover, sim.contact, kind))
    if key not in _TABLE_CACHE:
        if len(_TABLE_CACHE) > 16:
            _TABLE_CACHE.clear()
        _TABLE_CACHE[key] = build_tables(sim, kind)
    return _TABLE_CACHE[key]


def _clip(x, lo, hi, out=None):
    """np.clip as two ufuncs (np.clip's wrapper costs several microseconds per call)."""
    return np.minimum(np.maximum(x, lo, out=out), hi, out=out)


# Where a rod's line leaves the sensing square (compiled; also callable from Python).
_chord = mk.chord


class SkinModel:
    """Two-layer FSR skin under one rigid indenter ("hemisphere" or "rod")."""

    def __init__(self, sim: SimConfig, skin: SkinConfig, indenter: str, rng: np.random.Generator,
                 support_stiffness_n_per_mm: float | None = None):
        if indenter not in INDENTERS:
            raise ValueError(f"indenter={indenter!r}: must be one of {INDENTERS}")
        if support_stiffness_n_per_mm is not None and not support_stiffness_n_per_mm > 0:
            raise ValueError(f"support_stiffness_n_per_mm={support_stiffness_n_per_mm!r}: must be > 0 or None (rigid)")
        self.sim, self.skin, self.kind, self.rng = sim, skin, indenter, rng
        self.k_support = support_stiffness_n_per_mm
        self.tab = tables_for(sim, indenter)
        self.law = SpacerLaw(sim.spacer)
        n = skin.n_taxels
        # --- mechanics (mechanics.contact_steps): tables on the indentation grid, geometry, state
        t = self.tab
        self._mech_tab = np.ascontiguousarray(np.stack([t.delta_mm, t.load, t.shear_extra, t.torsion_extra,
                                                        t.friction_radius_mm]), dtype=float)
        half = sim.spacer.width / 2
        self._half = half
        k0 = float(self.law.shear_stiffness_kpa_per_mm(0.0)) * 1e-3  # N/mm per mm^2
        self._mech_geo = np.array([t.d_delta, -1.0 if self.k_support is None else self.k_support, half,
                                   sim.spacer.width**2, k0 * sim.spacer.width**2, k0, sim.spacer.width**4 / 6.0])
        self.friction = StickSlip(sim.cover.friction, sim.cover.kinetic, sim.cover.aging_s, sim.cover.overshoot)
        self._contact = np.zeros(mk.CONTACT_SIZE)  # previous pose, configuration serial, last configuration
        self._contact[mk.C_CONFIG:] = np.nan  # the first step is a new configuration
        self._model_id = next(_MODEL_IDS)
        self._maps_cache: tuple | None = None  # (config_key, (2, n, n) maps) of the last frame computed
        # --- quadrature over each taxel's electrode
        g, w = np.polynomial.legendre.leggauss(sim.contact.quad_points)
        centres = skin.taxel_centres_mm()
        self._q = (centres[:, None] + 0.5 * skin.electrode_mm * g[None, :]).ravel()  # (n*q,)
        self._qw = 0.5 * w  # sums to 1
        self._nq = sim.contact.quad_points
        qx, qy = np.meshgrid(self._q, self._q)  # [y, x]
        self._lattice32 = hex_cell_pattern(qx, qy, sim.spacer.cell, sim.spacer.lattice_contrast).astype(np.float32)
        self._q32 = self._q.astype(np.float32)
        self._lattice_windows: dict[int, np.ndarray] = {}  # width -> (.., .., w*q, w*q) strided views
        self._centres = centres
        self._half_electrode = 0.5 * skin.electrode_mm
        # (n, n*q) Gauss weights of each taxel's block of quadrature points (taxel means as matmuls)
        self._taxel_weights = np.kron(np.eye(n), self._qw[None, :]).astype(np.float32)
        self._build_lookups()
        # --- transduction and readout
        self.fsr = (FSRLayer(sim.fsr, (n, n), rng), FSRLayer(sim.fsr, (n, n), rng))
        self.readout = MatrixReadout(sim.readout, skin.adc_bits, n)
        r = sim.readout
        self.baseline_counts = np.clip(rng.normal(r.baseline_counts, r.baseline_sd_counts, size=(2, n, n)), 0, None)
        self._last_maps: np.ndarray | None = None  # (2, n, n) pressure at the last frame
        period = skin.frame_period_ms * 1e-3
        slot = np.arange(2 * n).reshape(2, n)
        self._row_offsets_s = (2 * n - 1 - slot)[None] * period / (2 * n)  # (1, 2, n) before frame end
        self._gains = np.stack([layer.gain for layer in self.fsr])  # (2, n, n), fixed per sheet
        # Idle sheet: no pressure at the last frame and both FSR memories exactly zero. Unloaded
        # frames then leave it so and read the floor conductance: constant counts plus noise.
        self._idle = True
        self._idle_counts: np.ndarray | None = None  # (2, n, n) float counts before noise
        self._last_t: float | None = None

    # ------------------------------------------------------------------ mechanics
    def step_many(self, t_s: np.ndarray, xyz_mm: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
        """Advance the contact through m commanded indenter poses (see the module docstring).

        t_s (m,), xyz_mm (m, 3) indenter pose in the skin frame, yaw_rad (m,). Returns the steps
        as records (m, mechanics.STEP_FIELDS): time, force, torque, indentation, contact, yaw,
        surface shift and rotation, slipping, cumulative slip, configuration serial."""
        out = np.empty((len(t_s), mk.STEP_FIELDS))
        mk.contact_steps(self.kind == "rod", self._mech_tab, self._mech_geo, self.friction.params,
                         self._contact, self.friction.state, np.ascontiguousarray(t_s, dtype=float),
                         np.ascontiguousarray(xyz_mm, dtype=float), np.ascontiguousarray(yaw_rad, dtype=float), out)
        return out

    def mech_state(self) -> np.ndarray:
        """The mechanics' state (contact and friction), for restore_mech_state."""
        return np.concatenate((self._contact, self.friction.state))

    def restore_mech_state(self, saved: np.ndarray) -> None:
        n = len(self._contact)
        self._contact[:] = saved[:n]
        self.friction.state[:] = saved[n:]

    def state_of(self, rec: np.ndarray) -> MechState:
        """The MechState of one step record (a row of step_many's output)."""
        return MechState(
            t_s=float(rec[mk.S_T]),
            force_n=rec[mk.S_FX:mk.S_FZ + 1],
            torque_z_nmm=float(rec[mk.S_TORQUE]),
            indentation_mm=float(rec[mk.S_DELTA]),
            contact_xy_mm=rec[mk.S_CX:mk.S_CY + 1],
            indenter_yaw_rad=float(rec[mk.S_YAW]),
            surface_shift_mm=rec[mk.S_UX:mk.S_UY + 1],
            surface_rotation_rad=float(rec[mk.S_THETA]),
            slipping=bool(rec[mk.S_SLIPPING]),
            slip_mm=rec[mk.S_SLIP_X:mk.S_SLIP_Y + 1],
            slip_rad=float(rec[mk.S_SLIP_RAD]),
            config_key=(self._model_id, int(rec[mk.S_SERIAL])),
        )

    def step(self, t_s: float, indenter_xyz_mm: np.ndarray, indenter_yaw_rad: float = 0.0) -> MechState:
        """Advance the contact to one commanded indenter pose (step_many for one step)."""
        rec = self.step_many(np.array([t_s], float), np.asarray(indenter_xyz_mm, float).reshape(1, 3),
                             np.array([indenter_yaw_rad], float))
        return self.state_of(rec[0])


    # ------------------------------------------------------------------ pressure maps
    def stack_height_mm(self, delta_mm):
        """Height of the cover surface above the deep sensing plane at the contact (mm)."""
        s = self.sim
        return s.cover.thickness + s.fsr.layer_thickness_mm + s.spacer.thickness - _clip(
            delta_mm, 0.0, 0.95 * s.spacer.thickness)

    def _build_lookups(self) -> None:
        """Resample the profile tables for nearest-bin lookups: in r^2 (hemisphere, no sqrt per
        point) or in the signed distance (rod), on a grid fine enough that nearest-bin error is
        far below the profile's own scale. Stored as (value, next row - value) float32 pairs in
        one complex64 array (one gather per point for both indentation rows), flattened with one
        guard column of zeros. Also the reach of each pair of rows (`_window_reach`)."""
        tab = self.tab
        if self.kind == "hemisphere":
            r2_max = float(tab.dist_mm[-1]) ** 2
            step = 0.01  # mm^2
            grid = np.arange(0.0, r2_max, step)
            at = np.sqrt(grid)
            self._lk_origin, self._lk_scale = 0.0, 1.0 / step
        else:
            step = 0.005  # mm
            grid = np.arange(tab.dist_mm[0], tab.dist_mm[-1], step)
            at = grid
            self._lk_origin, self._lk_scale = float(tab.dist_mm[0]), 1.0 / step
        self._lk_n = len(grid) + 1

        def pairs(table):
            fine = np.zeros((table.shape[0], self._lk_n), dtype=np.float32)
            for k in range(table.shape[0]):
                fine[k, :-1] = np.interp(at, tab.dist_mm, table[k])
            out = np.empty((table.shape[0] - 1, self._lk_n, 2), dtype=np.float32)
            out[..., 0] = fine[:-1]
            out[..., 1] = fine[1:] - fine[:-1]
            return out.view(np.complex64).ravel()

        self._lk_sup = pairs(tab.superficial_kpa)
        self._lk_deep = pairs(tab.deep_kpa)
        # Per pair of rows (k, k+1): the larger magnitude on the coarse grid, and (hemisphere) the
        # radius beyond which the superficial profile stays below WINDOW_EPS of its peak.
        self._pair_max_sup = np.maximum(np.abs(tab.superficial_kpa[:-1]), np.abs(tab.superficial_kpa[1:]))
        self._pair_max_deep = np.maximum(np.abs(tab.deep_kpa[:-1]), np.abs(tab.deep_kpa[1:]))
        self._reach_sup = self._window_reach(self._pair_max_sup, np.ones(1))
        self._tilt_table = np.stack([tab.tilt_gamma, tab.tilt_logz], axis=-1)
        self._dist_row = tab.dist_mm[None, :]

    def _window_reach(self, pair_max: np.ndarray, factor: np.ndarray) -> np.ndarray:
        """Radius (mm) beyond which pair_max (M, n_dist) x factor (M or 1, n_dist) stays below
        WINDOW_EPS of the row's peak; the coarse grid's next-but-one node bounds the fine table's
        interpolation and the nearest-bin rounding."""
        dist = self.tab.dist_mm
        bound = pair_max * factor
        thr = WINDOW_EPS * pair_max.max(axis=1, keepdims=True)
        above = bound > thr
        last = len(dist) - 1 - np.argmax(above[:, ::-1], axis=1)
        last = np.where(above.any(axis=1), last, -2)
        return dist[_clip(last + 2, 0, len(dist) - 1)]

    def _delta_index(self, delta: np.ndarray):
        x = _clip(delta / self.tab.d_delta, 0.0, len(self.tab.delta_mm) - 1.000001)
        i = x.astype(np.int64)
        return i, (x - i)

    def _lookup_pairs(self, flat: np.ndarray, i: np.ndarray, t32: np.ndarray, coord: np.ndarray) -> np.ndarray:
        """Profile (float32) at coord (N, a, b), r^2 or signed distance, overwritten, for frames
        with indentation row i + t: nearest bin, linear between the two rows."""
        n = self._lk_n
        if self._lk_origin != 0.0:
            coord -= self._lk_origin
        coord *= self._lk_scale
        coord += 0.5
        j = coord.astype(np.int32)
        _clip(j, 0, n - 1, out=j)  # guard column: zero outside the table
        j += (i * n).astype(np.int32)[:, None, None]
        pair = flat.take(j)
        val = pair.imag * t32[:, None, None]
        val += pair.real
        return val

    def _tilt(self, i: np.ndarray, t: np.ndarray, shift: np.ndarray):
        """Exponential-tilt rate and log-normaliser giving a deep-CoP shift (mm) at each frame."""
        tab = self.tab
        ds = tab.tilt_shift_mm[1] - tab.tilt_shift_mm[0]
        x = _clip(shift / ds, 0.0, len(tab.tilt_shift_mm) - 1.000001)
        si = x.astype(np.int64)
        su = x - si

        # both tables at once: (n_delta, n_shift, 2) [gamma, logz]
        table = self._tilt_table
        su, t = su[:, None], t[:, None]
        a = table[i, si] * (1 - su) + table[i, si + 1] * su
        b = table[i + 1, si] * (1 - su) + table[i + 1, si + 1] * su
        gl = a * (1 - t) + b * t
        return gl[:, 0], gl[:, 1]

    def _window(self, centre: np.ndarray, reach: np.ndarray):
        """Taxel windows (start_y, start_x) (M,), common width, and which frames have one: every
        taxel whose electrode comes within `reach` (M,) of `centre` (M, 2), square, inside the
        array (shifted inward at the edges; frames whose reach misses the array have none)."""
        n, pitch = self.skin.n_taxels, self.skin.pitch_mm
        x0 = self._centres[0]
        lo = np.ceil((centre - reach[:, None] - self._half_electrode - x0) / pitch)
        hi = np.floor((centre + reach[:, None] + self._half_electrode - x0) / pitch)
        lo = _clip(lo, 0, n).astype(np.int64)
        hi = _clip(hi, -1, n - 1).astype(np.int64)
        has = np.all(hi >= lo, axis=1)
        width = int((hi - lo + 1)[has].max()) if has.any() else 0
        start = np.minimum(lo, n - width)
        return start[:, 1], start[:, 0], width, has

    def _grid_axes(self, sy: np.ndarray, sx: np.ndarray, width: int):
        """Quadrature rows/cols (M, width*q) of the windows and their coordinates (float32)."""
        ar = np.arange(width * self._nq)
        rows = (sy * self._nq)[:, None] + ar
        cols = (sx * self._nq)[:, None] + ar
        return rows, cols, self._q32[rows], self._q32[cols]

    def _window_fields(self, batch: StateBatch):
        """Pressure (kPa, float32) at the quadrature points of each layer inside a window around
        its contact. Returns per layer (frames (M,), start_y (M,), start_x (M,), width in taxels,
        field (M, width*q, width*q) [y, x]); outside the window and for unloaded frames it is
        zero (or, for the hemisphere, below WINDOW_EPS of the profile's peak)."""
        fz = batch.force_n[:, 2]
        live = np.flatnonzero(fz > 0)
        n = self.skin.n_taxels
        empty = (live[:0], live[:0], live[:0], 0, np.zeros((0, 0, 0), np.float32))
        if len(live) == 0:
            return empty, empty
        b = batch if len(live) == len(fz) else StateBatch(**{k: v[live] for k, v in vars(batch).items()})
        delta, fz, ft = b.indentation_mm, b.force_n[:, 2], b.force_n[:, :2]
        a = b.contact_xy_mm
        cd = a + b.surface_shift_mm  # contact in the deep frame
        h_eff = self.stack_height_mm(delta)
        ft_mag = np.hypot(ft[:, 0], ft[:, 1])
        shift = ft_mag * h_eff / fz  # moment balance: F_t H = F_z shift
        i, t = self._delta_index(delta)
        t32 = t.astype(np.float32)
        gamma, logz = self._tilt(i, t, shift)
        f32 = np.float32
        if self.kind == "rod":
            full = (np.zeros(len(live), np.int64),) * 2
            rows, cols, qy, qx = self._grid_axes(*full, n)
            sup, deep = self._rod_fields(b, i, t32, gamma, logz, h_eff, qx - a[:, 0:1].astype(f32),
                                         qy - a[:, 1:2].astype(f32), qx - cd[:, 0:1].astype(f32),
                                         qy - cd[:, 1:2].astype(f32))
            return (live, *full, n, sup), (live, *full, n, deep * self._lattice32[None])
        # superficial: radial profile around the contact, in the superficial frame
        sy, sx, width, has = self._window(a, self._reach_sup[i])
        k = np.flatnonzero(has)
        rows, cols, qy, qx = self._grid_axes(sy[k], sx[k], width)
        dx = qx - a[k, 0:1].astype(f32)
        dy = qy - a[k, 1:2].astype(f32)
        r2 = (dx * dx)[:, None, :] + (dy * dy)[:, :, None]
        sup = (live[k], sy[k], sx[k], width, self._lookup_pairs(self._lk_sup, i[k], t32[k], r2))
        # deep: spread profile tilted along the shear, times the lattice pattern; its window
        # bounds the profile times the largest tilt factor exp(|gamma| r - logz)
        tilt_max = np.exp(np.abs(gamma)[:, None] * self._dist_row - logz[:, None])
        sy, sx, width, has = self._window(cd, self._window_reach(self._pair_max_deep[i], tilt_max))
        k = np.flatnonzero(has)
        rows, cols, qy, qx = self._grid_axes(sy[k], sx[k], width)
        dx = qx - cd[k, 0:1].astype(f32)
        dy = qy - cd[k, 1:2].astype(f32)
        # shear direction (0 without shear: ft is 0 there, so no 0/0)
        nrm = (ft[k] / np.maximum(ft_mag[k, None], _TINY)).astype(f32)
        g = (gamma[k, None] * nrm).astype(f32)  # tilt along the shear direction
        half_logz = 0.5 * logz[k, None].astype(f32)
        ex = np.exp(g[:, 0, None] * dx - half_logz)
        ey = np.exp(g[:, 1, None] * dy - half_logz)
        field = self._lookup_pairs(self._lk_deep, i[k], t32[k], (dx * dx)[:, None, :] + (dy * dy)[:, :, None])
        field *= ey[:, :, None] * ex[:, None, :]
        blocks = self._lattice_windows.get(width)
        if blocks is None:
            blocks = np.lib.stride_tricks.sliding_window_view(self._lattice32, (width * self._nq,) * 2)
            self._lattice_windows[width] = blocks
        field *= blocks[sy[k] * self._nq, sx[k] * self._nq]  # the lattice pattern under each window
        return sup, (live[k], sy[k], sx[k], width, field)

    def _rod_fields(self, b, i, t32, gamma, logz, h_eff, dxs, dys, dxd, dyd):
        """Rod line load on the full grid (live frames only), both layers [y, x], float32."""
        f32 = np.float32
        yaw = b.indenter_yaw_rad
        yaw_s = yaw - b.surface_rotation_rad  # rod axis in the superficial frame
        ps = ((-np.sin(yaw_s)).astype(f32)[:, None] * dxs)[:, None, :] + (np.cos(yaw_s).astype(f32)[:, None] * dys)[:, :, None]
        sup = self._lookup_pairs(self._lk_sup, i, t32, ps)
        fz = b.force_n[:, 2]
        cd = b.contact_xy_mm + b.surface_shift_mm
        chords = np.array([_chord(float(c[0]), float(c[1]), float(w), self._half) for c, w in zip(cd, yaw, strict=True)])
        length = np.maximum(chords[:, 1] - chords[:, 0], 1e-9)
        line_q = fz / length  # N/mm
        i_s = (chords[:, 1] ** 3 - chords[:, 0] ** 3) / 3.0
        with np.errstate(invalid="ignore", divide="ignore"):
            # torsion: traction T s / I_s across the line; its moment shifts the deep line by T H s / (I_s q)
            twist = np.arctan(b.torque_z_nmm * h_eff / (i_s * line_q))
        yaw_d = yaw + twist
        ex, ey = np.cos(yaw_d).astype(f32)[:, None], np.sin(yaw_d).astype(f32)[:, None]
        px, py = -ey * dxd, ex * dyd  # perp = px + py, along = ax + ay
        ax, ay = ex * dxd, ey * dyd
        ft = b.force_n[:, :2]
        f_perp = -ft[:, 0] * ey[:, 0] + ft[:, 1] * ex[:, 0]
        f_along = ft[:, 0] * ex[:, 0] + ft[:, 1] * ey[:, 0]
        g = (np.sign(f_perp) * gamma).astype(f32)[:, None]
        deep = self._lookup_pairs(self._lk_deep, i, t32, px[:, None, :] + py[:, :, None])
        tx = np.exp(g * px - logz.astype(f32)[:, None])
        ty = np.exp(g * py)
        deep *= ty[:, :, None] * tx[:, None, :]
        # along-axis shear: its moment is balanced by a linear load gradient along the line
        mid = 0.5 * (chords[:, 0] + chords[:, 1])
        beta = (f_along * h_eff / (line_q * length**3 / 12.0)).astype(f32)[:, None]
        ramp = (1.0 + beta * (ax - mid.astype(f32)[:, None]))[:, None, :] + (beta * ay)[:, :, None]
        np.maximum(ramp, 0.0, out=ramp)
        deep *= ramp
        return sup, deep

    def _taxel_sums(self, out: np.ndarray, layer) -> np.ndarray:
        """Writes the taxel means (float64) of one layer's windowed fields into out (N, 16, 16)
        (left as it is outside the windows: pass zeros)."""
        frames_idx, sy, sx, width, field = layer
        if len(frames_idx) == 0:
            return out
        wq = width * self._nq
        wm = self._taxel_weights[:width, :wq]  # (width, wq): block rows of the Gauss weights
        # stacked small products (one large GEMM would wake OpenBLAS's thread pool)
        tax = np.matmul(wm, np.matmul(field, wm.T))  # (M, width, width)
        ar = np.arange(width)
        out[frames_idx[:, None, None], (sy[:, None] + ar)[:, :, None], (sx[:, None] + ar)[:, None, :]] = tax
        return out

    def pressure_fields(self, batch: StateBatch) -> tuple[np.ndarray, np.ndarray]:
        """Pressure (kPa, float32) at the quadrature points (N, n*q, n*q) of both layers, [y, x]."""
        n_all = len(batch.t_s)
        nq = self.skin.n_taxels * self._nq
        out = []
        for frames_idx, sy, sx, width, field in self._window_fields(batch):
            full = np.zeros((n_all, nq, nq), np.float32)
            ar = np.arange(width * self._nq)
            rows = (sy * self._nq)[:, None] + ar
            cols = (sx * self._nq)[:, None] + ar
            full[frames_idx[:, None, None], rows[:, :, None], cols[:, None, :]] = field
            out.append(full)
        return out[0], out[1]

    def pressure_maps(self, states: list[MechState]) -> tuple[np.ndarray, np.ndarray]:
        """(N, 16, 16) mean pressure (kPa) over each taxel's electrode: superficial, deep."""
        maps = self._maps(states)
        return maps[:, 0], maps[:, 1]

    def _maps(self, states: list[MechState]) -> np.ndarray:
        """(N, 2, 16, 16) mean pressure (kPa) over each taxel's electrode, [superficial, deep]."""
        n = self.skin.n_taxels
        cached = self._maps_cache
        if cached is not None and all(s.config_key == cached[0] for s in states):
            # a hold: the same loading configuration as the last frame computed, the same maps
            maps = np.empty((len(states), 2, n, n))
            maps[:] = cached[1]
            return maps
        maps = np.zeros((len(states), 2, n, n))
        sup, deep = self._window_fields(stack_states(states))
        self._taxel_sums(maps[:, 0], sup)
        self._taxel_sums(maps[:, 1], deep)
        key = states[-1].config_key if states else None
        self._maps_cache = None if key is None else (key, maps[-1].copy())
        return maps

    # ------------------------------------------------------------------ frames
    def reseed(self, rng: np.random.Generator) -> None:
        """New scan-jitter and readout-noise draws from rng (a new trial); the sheet's gains and
        baselines stay."""
        self.rng = rng

    def _row_times(self, t_s: np.ndarray) -> np.ndarray:
        """(N, 2, n) sampling instants: t_s[k] ends the frame; rows sampled in sequence before it."""
        t = t_s[:, None, None] - self._row_offsets_s
        jit = self.sim.readout.scan_jitter_ms * 1e-3
        if jit > 0:
            t = t + self.rng.normal(0.0, jit, size=t.shape)
        return t

    def frames(self, states: list[MechState], t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(superficial, deep) uint16 counts (N, 16, 16) for frames completed at t_s (N,)."""
        t_s = np.asarray(t_s, dtype=float).reshape(-1)
        if len(states) != len(t_s):
            raise ValueError(f"frames: {len(states)} states for {len(t_s)} frame times; pass one state per frame")
        if len(t_s) == 0:
            empty = np.zeros((0, self.skin.n_taxels, self.skin.n_taxels), np.uint16)
            return empty, empty.copy()
        n = self.skin.n_taxels
        if self._idle and not any(s.force_n[2] > 0.0 for s in states):
            return self._idle_frames(t_s)
        maps = self._maps(states)  # (N, 2, n, n)
        prev_maps = np.empty_like(maps)
        prev_maps[0] = maps[0] if self._last_maps is None else self._last_maps
        prev_maps[1:] = maps[:-1]
        prev_t = np.empty_like(t_s)
        prev_t[0] = t_s[0] - self.skin.frame_period_ms * 1e-3 if self._last_t is None else self._last_t
        prev_t[1:] = t_s[:-1]
        dt = t_s - prev_t  # time since the previous frame
        span = np.maximum(dt, 1e-9)
        rows_t = self._row_times(t_s)
        w_prev = _clip((t_s[:, None, None] - rows_t) / span[:, None, None], 0.0, 1.0)[..., None]
        sampled = maps * (1 - w_prev) + prev_maps * w_prev  # each row at its own instant
        self._last_maps, self._last_t = maps[-1], float(t_s[-1])
        eff = advance_layers(self.fsr, sampled, dt)  # both layers at once (N, 2, n, n)
        self._idle = not (maps[-1].any() or any(f.play.any() or f.lag.any() for f in self.fsr))
        g = conductance_layers(self.fsr, eff, self._gains)
        volts = self.readout.column_volts(g.reshape(-1, n, n)).reshape(-1, 2, n, n)
        out = (self.readout.counts(volts) + self.baseline_counts[None]).transpose(1, 0, 2, 3)  # (2, N, n, n)
        noise = self.sim.readout.noise_counts
        if noise > 0:
            out += self.rng.normal(0.0, noise, size=out.shape)
        np.rint(out, out=out)
        counts = _clip(out, 0, self.readout.full_scale, out=out).astype(np.uint16)
        return counts[0], counts[1]

    def _idle_frames(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """frames() for unloaded states on an idle sheet: the full pipeline's result (zero
        pressure, floor conductance, constant column voltages), with the same draws from rng."""
        n = self.skin.n_taxels
        if self._idle_counts is None:
            g = conductance_layers(self.fsr, np.zeros((1, 2, n, n)), self._gains)
            volts = self.readout.column_volts(g.reshape(-1, n, n)).reshape(-1, 2, n, n)
            self._idle_counts = (self.readout.counts(volts) + self.baseline_counts[None])[0]
        self._row_times(t_s)  # the scan jitter draws (they do not matter at zero pressure)
        out = np.repeat(self._idle_counts[:, None], len(t_s), axis=1)  # (2, N, n, n)
        noise = self.sim.readout.noise_counts
        if noise > 0:
            out += self.rng.normal(0.0, noise, size=out.shape)
        np.rint(out, out=out)
        counts = _clip(out, 0, self.readout.full_scale, out=out).astype(np.uint16)
        self._last_maps, self._last_t = np.zeros((2, n, n)), float(t_s[-1])
        return counts[0], counts[1]

    # ------------------------------------------------------------------ board description
    def calibration(self) -> dict:
        """What the readout board reports about itself: geometry, scan and readout settings."""
        s, r = self.skin, self.sim.readout
        return {
            "layers": list(s.layers),
            "n_taxels": s.n_taxels,
            "pitch_mm": s.pitch_mm,
            "electrode_mm": s.electrode_mm,
            "taxel_centres_mm": s.taxel_centres_mm().tolist(),
            "adc_bits": s.adc_bits,
            "adc_full_scale": int(2**s.adc_bits - 1),
            "frame_period_ms": s.frame_period_ms,
            "scan_order": "superficial rows 0..15, then deep rows 0..15; frame time = end of scan",
            "divider_kohm": r.divider_kohm,
            "supply_v": r.supply_v,
            "indenter": self.kind,
        }
