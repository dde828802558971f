"""The simulated two-layer skin under one rigid indenter: mechanics step and frame pipeline.

Frames. The deep layer is bonded to the support: the skin frame is the deep layer's frame
(origin at the array centre, x along columns, y along rows). The superficial layer rides on the
spacer: it is displaced by `surface_shift_mm` and rotated by `surface_rotation_rad` about the
contact point, so a point x_s of the superficial frame sits at
    x_deep = a + u + R(theta) (x_s - a),  a = contact_xy_mm, u = surface_shift_mm.

Mechanics (`step`, scalar, ~1 kHz). The realised indentation comes from the contact tables and
the series support compliance; the spacer's shear stiffness (rising with compression) loads
the stick-slip friction at the cover, which gives the tangential force and torque.

Pressure maps (`pressure_maps`, vectorised). Both come from the laminate-on-lattice solution
(`contact`, `laminate`). Deep: the lattice's pressure around the contact's deep-frame
position, times the lattice's cell pattern. Superficial, in the superficial frame: the mean of the
contact pressure under the cover around the contact point and that lattice pressure (its core
lies between the sheet's films, loaded by the contact above and the lattice below; `contact`). The
shear's couple F_t H about the deep plane (H the height of the cover above it) adds the
laminate's first-order response to both. The cover's part of the lever acts under the contact
(the indenter takes a share), from the contact tables. The lattice's part, F_t h_L, and the
columns' lean F_z u (the sheet's travel u leans the lattice's columns under the contact; their
thrust joins the lattice's shear) are handed over the whole pad by the in-plane-stiff sheet and
end at the pad's four sides, wherever the contact is: half through the sheet (which tilts), half
straight onto the deep sheet (`contact.ContactTables.edge_deep_kpa`). So the deep plane's moment is
the load's where the sheared stack holds it. A torque's lattice part ends at the sides alike, as
the rotation of a uniform traction field. Neither FSR reads tension. For the rod, torsion loads
the line with traction proportional to the distance along it, whose local moments (the cover's
lever) rotate the deep line.
Each taxel integrates its electrode footprint with Gauss points.

Frames (`frames`, or `frames_batch` on arrays): row-sequential sampling instants, FSR
hysteresis/creep and conductance, passive-matrix readout with crosstalk, offsets, noise and
quantisation. The per-frame arithmetic (maps included) runs in one compiled call
(`frame_kernels.frames_kernel`); this class holds the tables and memories as arrays and the
numpy Generator the kernel draws from (the same standard normals in the same order as the
vectorised numpy pipeline took them).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim import frame_kernels as fk
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim import table_cache
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import ContactTables, build_tables
from layerskin_exp.sim.friction import StickSlip
from layerskin_exp.sim.fsr import FSRLayer, conductance_layers
from layerskin_exp.sim.readout import MatrixReadout
from layerskin_exp.sim.spacer import SpacerLaw, hex_cell_pattern

INDENTERS = ("hemisphere", "rod")
# The hemisphere's fields are evaluated in a window around the contact: outside it each layer's
# profile and its couple response are below this fraction of their peaks.
WINDOW_EPS = fk.WINDOW_EPS


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
_KERNELS_LOADED = False  # the frame kernels are loaded once per process (SkinModel._load_kernels)


def tables_for(sim: SimConfig, kind: str, radius_mm: float | None = None) -> ContactTables:
    """Contact tables for a design, computed once per distinct (spacer, cover, contact) config
    (in this process, and on disk for later processes: see table_cache)."""
    key = repr((sim.spacer, sim.cover, sim.sheet, sim.fsr.layer_thickness_mm, sim.contact, kind, radius_mm))
    if key not in _TABLE_CACHE:
        if len(_TABLE_CACHE) > 16:
            _TABLE_CACHE.clear()
        _TABLE_CACHE[key] = table_cache.load_or_build(key, lambda: build_tables(sim, kind, radius_mm))
    return _TABLE_CACHE[key]


def _clip(x, lo, hi, out=None):
    """np.clip as two ufuncs (np.clip's wrapper costs several microseconds per call)."""
    return np.minimum(np.maximum(x, lo, out=out), hi, out=out)


# Where a rod's line leaves the sensing square (compiled; also callable from Python).
_chord = mk.chord


class SkinModel:
    """Two-layer FSR skin under one rigid indenter ("hemisphere" or "rod")."""

    def __init__(self, sim: SimConfig, skin: SkinConfig, indenter: str, rng: np.random.Generator,
                 support_stiffness_n_per_mm: float | None = None, contact_radius_mm: float | None = None):
        if indenter not in INDENTERS:
            raise ValueError(f"indenter={indenter!r}: must be one of {INDENTERS}")
        if support_stiffness_n_per_mm is not None and not support_stiffness_n_per_mm > 0:
            raise ValueError(f"support_stiffness_n_per_mm={support_stiffness_n_per_mm!r}: must be > 0 or None (rigid)")
        self.sim, self.skin, self.kind, self.rng = sim, skin, indenter, rng
        self.k_support = support_stiffness_n_per_mm
        # contact_radius_mm: only for comparisons with a reference of another geometry (the
        # FEM section's cylinder); the rig's indenter and rod are layerskin_exp.rig's
        self.tab = tables_for(sim, indenter, contact_radius_mm)
        self.law = SpacerLaw(sim.spacer)
        n = skin.n_taxels
        # --- mechanics (mechanics.contact_steps): tables on the indentation grid, geometry, state
        t = self.tab
        self._mech_tab = np.ascontiguousarray(np.stack([t.delta_mm, t.load, t.shear_extra, t.torsion_extra,
                                                        t.friction_radius_mm, t.cover_shear, t.cover_torsion]),
                                              dtype=float)
        half = sim.spacer.width_mm / 2
        self._half = half
        k0 = float(self.law.shear_stiffness_kpa_per_mm(0.0)) * 1e-3  # N/mm per mm^2
        self._mech_geo = np.array([t.d_delta, -1.0 if self.k_support is None else self.k_support, half,
                                   sim.spacer.width_mm**2, k0 * sim.spacer.width_mm**2, k0, sim.spacer.width_mm**4 / 6.0])
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
        self._lattice32 = hex_cell_pattern(qx, qy, sim.spacer.cell_mm, sim.spacer.lattice_contrast).astype(np.float32)
        self._quad32 = np.concatenate([self._q, self._qw]).astype(np.float32)  # coordinates, then weights
        self._centres = centres
        self._half_electrode = 0.5 * skin.electrode_mm
        self._build_lookups()
        # --- transduction and readout
        self.fsr = (FSRLayer(sim.fsr, (n, n), rng), FSRLayer(sim.fsr, (n, n), rng))
        self.readout = MatrixReadout(sim.readout, skin.adc_bits, n)
        r = sim.readout
        self.baseline_counts = np.clip(rng.normal(r.baseline_counts, r.baseline_sd_counts, size=(2, n, n)), 0, None)
        period = skin.frame_period_ms * 1e-3
        slot = np.arange(2 * n).reshape(2, n)
        self._row_offsets_s = (2 * n - 1 - slot) * period / (2 * n)  # (2, n) before the frame end
        self._gains = np.stack([layer.gain for layer in self.fsr])  # (2, n, n), fixed per sheet
        # the FSR memories of both layers in one array; each FSRLayer keeps views of it
        self._play, self._lag = np.zeros((2, n, n)), np.zeros((2, n, n))
        for k, layer in enumerate(self.fsr):
            layer.play, layer.lag = self._play[k], self._lag[k]
        self._last_maps = np.zeros((2, n, n))  # pressure at the last frame
        self._memory = np.zeros(2)  # [time of the last frame, whether there was one]
        self._params = self._kernel_params()
        self._tables = self._kernel_tables()
        self.maps_computed = 0  # states whose pressure maps were computed (not reused in a hold)
        # Idle sheet: no pressure at the last frame and both FSR memories exactly zero. Unloaded
        # frames then leave it so and read the floor conductance: constant counts plus noise.
        self._idle = True
        self._load_kernels()
        self._idle_counts = self._floor_counts()  # (2, n, n) float counts before noise

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
        """Height of the cover surface above the deep sensing plane at the contact (mm): the
        stack less the lattice's compression under the contact at indentation delta_mm."""
        return np.interp(delta_mm, self.tab.delta_mm, self.tab.height_mm)

    def _build_lookups(self) -> None:
        """Resample the profile tables for nearest-bin lookups: in r^2 (hemisphere, no sqrt per
        point) or in the signed distance (rod), on a grid fine enough that nearest-bin error is
        far below the profile's own scale. Stored as (value, next row - value) float32 pairs per
        pair of indentation rows, with one guard column of zeros, profile and couple response
        side by side: `_lk` (2, n_delta - 1, n_fine, 4) [the cover's (the superficial core's
        contact half), deep]. Also the window reach of each pair of rows (`_bounds`: the
        cover's and the lattice's; the superficial core spans both), the stack's and the
        lattice's height per row (`_rows`) and the lattice's route across the pad's sides at the
        quadrature coordinates (`_edge`), see frame_kernels."""
        tab = self.tab
        if self.kind == "hemisphere":
            # the deep profile is broad and smooth, the cover's narrow (the contact and the
            # cover's spread) with steep edges: the same bins, 16 times finer in r^2 for it
            r2_max = float(tab.dist_mm[-1]) ** 2
            step_deep = 0.02  # mm^2
            grid = np.arange(0.0, r2_max, step_deep)
            at_layer = (np.sqrt(grid / 16.0), np.sqrt(grid))
            self._lk_origin, self._lk_scale, self._lk_scale_deep = 0.0, 16.0 / step_deep, 1.0 / step_deep
            self._lk_origin_deep = 0.0
        else:  # signed distance to the line; the superficial table spans half the deep one, twice as fine
            step = 0.005  # mm
            grid = np.arange(tab.dist_mm[0], tab.dist_mm[-1], step)
            at_layer = (0.5 * grid, grid)
            self._lk_origin, self._lk_scale = 0.5 * float(tab.dist_mm[0]), 2.0 / step
            self._lk_origin_deep, self._lk_scale_deep = float(tab.dist_mm[0]), 1.0 / step
        n_fine = len(grid) + 1

        def resample(table, at, per_r=False):
            fine = np.zeros((table.shape[0], n_fine), dtype=np.float32)
            for k in range(table.shape[0]):
                v = np.interp(at, tab.dist_mm, table[k])
                if per_r:  # the cos(phi) mode's amplitude / r (it vanishes linearly on the axis)
                    v = v / np.maximum(at, 1e-9)
                    v[at <= 0.0] = v[at > 0.0][0] if (at > 0.0).any() else 0.0
                fine[k, :-1] = v
            return fine

        def quads(profile, couple, at, per_r):
            out = np.empty((profile.shape[0] - 1, n_fine, 4), dtype=np.float32)
            for j, a in enumerate((resample(profile, at), resample(couple, at, per_r))):
                out[..., 2 * j], out[..., 2 * j + 1] = a[:-1], a[1:] - a[:-1]
            return out

        hemi = self.kind == "hemisphere"
        self._lk = np.ascontiguousarray(np.stack([
            quads(tab.cover_kpa, tab.cover_couple_kpa, at_layer[0], hemi),
            quads(tab.deep_kpa, tab.deep_couple_kpa, at_layer[1], hemi)]))
        # Per pair of rows (k, k+1): how far from the contact either the profile or its couple
        # response exceeds WINDOW_EPS of its own peak, for each layer.

        def reach(*tables):
            out = np.zeros(len(tab.delta_mm) - 1)
            for table in tables:
                pair_max = np.maximum(np.abs(table[:-1]), np.abs(table[1:]))
                out = np.maximum(out, self._window_reach(pair_max, np.ones(1)))
            return out

        self._bounds = np.ascontiguousarray(np.column_stack([
            reach(tab.cover_kpa, tab.cover_couple_kpa),
            reach(tab.deep_kpa, tab.deep_couple_kpa)]))
        self._dist = np.ascontiguousarray(tab.dist_mm, dtype=float)
        self._rows = np.ascontiguousarray(np.column_stack([tab.height_mm, tab.lattice_height_mm]), dtype=float)
        # the lattice's route across a side of the pad (per unit couple per mm along it), at the
        # quadrature coordinates (the same along x and y): [deep sheet, the lattice's top]
        self._edge = np.ascontiguousarray(np.stack([np.interp(self._q, tab.edge_dist_mm, tab.edge_deep_kpa, 0.0, 0.0),
                                                    np.interp(self._q, tab.edge_dist_mm, tab.edge_top_kpa, 0.0, 0.0)]),
                                          dtype=np.float32)

    def _kernel_tables(self) -> tuple:
        """The kernels' table arguments after the state (frame_kernels: prm, lk, rows, bounds,
        dist, quad, lattice, edge)."""
        return (self._params, self._lk, self._rows, self._bounds, self._dist, self._quad32, self._lattice32,
                self._edge)

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

    def _kernel_params(self) -> np.void:
        """The kernels' parameter record (frame_kernels.PARAMS)."""
        s, skin, tab = self.sim, self.skin, self.tab
        prm = fk.transduction_params(s.fsr, s.readout, skin.adc_bits)
        prm["n_taxels"], prm["quad_points"], prm["rod"] = skin.n_taxels, self._nq, float(self.kind == "rod")
        prm["first_centre_mm"], prm["pitch_mm"] = self._centres[0], skin.pitch_mm
        prm["half_electrode_mm"], prm["half_pad_mm"] = self._half_electrode, self._half
        prm["side_inset_mm"] = float(tab.side_inset_mm)
        # the stretched sheet's reach spans the pad, so it answers load past the sides as a rigid body
        prm["fold_sides"] = float(self.kind == "hemisphere" and s.sheet.large_deflection)
        prm["delta_step_mm"], prm["last_delta_row"] = tab.d_delta, len(tab.delta_mm) - 1.000001
        prm["lk_origin"], prm["lk_scale"] = self._lk_origin, self._lk_scale
        prm["lk_origin_deep"], prm["lk_scale_deep"] = self._lk_origin_deep, self._lk_scale_deep
        prm["frame_period_s"] = skin.frame_period_ms * 1e-3
        prm["reuse_maps"] = 1.0
        return prm

    @property
    def reuse_maps(self) -> bool:
        """Whether states repeating the previous loading configuration (holds) reuse its maps."""
        return bool(self._params["reuse_maps"])

    @reuse_maps.setter
    def reuse_maps(self, on: bool) -> None:
        self._params["reuse_maps"] = 1.0 if on else 0.0

    @property
    def _maps_cache(self) -> tuple | None:
        """(config_key, (2, n, n) maps) of the last state whose maps were computed, or None."""
        serial = int(self._cache_serial[0])
        return None if serial < 0 else ((self._model_id, serial), self._cache_maps.copy())

    @_maps_cache.setter
    def _maps_cache(self, value: tuple | None) -> None:
        if not hasattr(self, "_cache_serial"):
            n = self.skin.n_taxels
            self._cache_serial = np.full(1, -1, dtype=np.int64)
            self._cache_maps = np.zeros((2, n, n))
        if value is None:
            self._cache_serial[0] = -1
        else:
            self._cache_serial[0] = self._serials([value[0]])[0]
            self._cache_maps[:] = value[1]

    def _serials(self, keys) -> np.ndarray:
        """(N,) int64 configuration serials of config keys (-1: none or another model's)."""
        mid = self._model_id
        return np.array([k[1] if k is not None and k[0] == mid else -1 for k in keys], dtype=np.int64)

    @staticmethod
    def _pack(batch: StateBatch) -> np.ndarray:
        """(N, frame_kernels.N_STATE) float64 state matrix of a batch (the kernels' layout)."""
        st = np.empty((len(batch.t_s), fk.N_STATE))
        st[:, fk.S_T] = batch.t_s
        st[:, fk.S_FX:fk.S_FZ + 1] = batch.force_n
        st[:, fk.S_TORQUE] = batch.torque_z_nmm
        st[:, fk.S_DELTA] = batch.indentation_mm
        st[:, fk.S_AX:fk.S_AY + 1] = batch.contact_xy_mm
        st[:, fk.S_YAW] = batch.indenter_yaw_rad
        st[:, fk.S_UX:fk.S_UY + 1] = batch.surface_shift_mm
        st[:, fk.S_ROT] = batch.surface_rotation_rad
        return st

    @staticmethod
    def _pack_states(states: list[MechState]) -> np.ndarray:
        """_pack(stack_states(states)) in one array construction."""
        rows = []
        for s in states:
            f, a, u = s.force_n, s.contact_xy_mm, s.surface_shift_mm
            rows.append((s.t_s, f[0], f[1], f[2], s.torque_z_nmm, s.indentation_mm, a[0], a[1],
                         s.indenter_yaw_rad, u[0], u[1], s.surface_rotation_rad))
        return np.array(rows, dtype=float).reshape(-1, fk.N_STATE)

    def pressure_fields(self, batch: StateBatch) -> tuple[np.ndarray, np.ndarray]:
        """Pressure (kPa, float32) at the quadrature points (N, n*q, n*q) of both layers, [y, x];
        zero for unloaded states and (hemisphere) outside each layer's window around the
        contact, where the profile is below WINDOW_EPS of its peak."""
        st = self._pack(batch)
        m = self.skin.n_taxels * self._nq
        sup = np.zeros((len(st), m, m), np.float32)
        deep = np.zeros((len(st), m, m), np.float32)
        fk.fields_kernel(st, *self._tables, sup, deep)
        return sup, deep

    def pressure_maps(self, states: list[MechState]) -> tuple[np.ndarray, np.ndarray]:
        """(N, 16, 16) mean pressure (kPa) over each taxel's electrode: superficial, deep."""
        maps = self._maps(states)
        return maps[:, 0], maps[:, 1]

    def _maps(self, states: list[MechState]) -> np.ndarray:
        """(N, 2, 16, 16) mean pressure (kPa) over each taxel's electrode, [superficial, deep]."""
        return self.maps_batch(stack_states(states), self._serials([s.config_key for s in states]))

    def maps_batch(self, batch: StateBatch, config_serial: np.ndarray) -> np.ndarray:
        """(N, 2, 16, 16) mean pressure (kPa) over each taxel's electrode, [superficial, deep],
        for a batch with its configuration serials (N,) (MechState.config_key[1]; -1: none):
        a state repeating the previous one's configuration (or the last computed) reuses it."""
        n = self.skin.n_taxels
        st = self._pack(batch)
        maps = np.empty((len(st), 2, n, n))
        serial = np.ascontiguousarray(config_serial, dtype=np.int64).reshape(-1)
        self.maps_computed += fk.maps_kernel(st, serial, *self._tables, self._cache_serial, self._cache_maps, maps)
        return maps

    # ------------------------------------------------------------------ frames
    def reseed(self, rng: np.random.Generator) -> None:
        """New scan-jitter and readout-noise draws from rng (a new trial); the sheet's gains and
        baselines stay."""
        self.rng = rng

    def frames(self, states: list[MechState], t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(superficial, deep) uint16 counts (N, 16, 16) for frames completed at t_s (N,)."""
        if len(states) != np.size(t_s):
            raise ValueError(f"frames: {len(states)} states for {np.size(t_s)} frame times; pass one state per frame")
        return self._frames_packed(self._pack_states(states), self._serials([s.config_key for s in states]), t_s)

    def frames_batch(self, batch: StateBatch, config_serial: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(superficial, deep) uint16 counts (N, 16, 16) for frames completed at t_s (N,), one
        state of the batch per frame; config_serial (N,) int64: each state's configuration
        serial (MechState.config_key[1] of this model; -1 if unknown), equal serials meaning
        an unchanged loading configuration whose pressure maps are reused."""
        if len(batch.t_s) != np.size(t_s) or np.size(config_serial) != np.size(t_s):
            raise ValueError(f"frames_batch: {len(batch.t_s)} states, {np.size(config_serial)} serials for "
                             f"{np.size(t_s)} frame times; pass one state and serial per frame")
        return self._frames_packed(self._pack(batch), config_serial, t_s)

    def frames_of_steps(self, recs: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """frames() for step records of this model (step_many's rows, one per frame): their
        leading columns are the frame kernels' state layout, their serials the hold cache's."""
        return self._frames_packed(np.ascontiguousarray(recs[:, :fk.N_STATE]),
                                   recs[:, mk.S_SERIAL].astype(np.int64), t_s)

    def _frames_packed(self, st: np.ndarray, config_serial, t_s) -> tuple[np.ndarray, np.ndarray]:
        """frames() on the kernels' state matrix st (N, N_STATE)."""
        t_s = np.ascontiguousarray(t_s, dtype=np.float64).reshape(-1)
        n_all, n = len(t_s), self.skin.n_taxels
        if n_all == 0:
            empty = np.zeros((0, n, n), np.uint16)
            return empty, empty.copy()
        if self._idle and not (st[:, fk.S_FZ] > 0.0).any():
            return self._idle_frames(t_s)
        serial = np.ascontiguousarray(config_serial, dtype=np.int64).reshape(-1)
        maps = np.empty((n_all, 2, n, n))
        counts = np.empty((2, n_all, n, n), np.uint16)
        idle, computed = fk.frames_kernel(st, serial, t_s, self.rng, *self._tables, self._row_offsets_s,
                                          self._gains, self.baseline_counts, self._play, self._lag,
                                          self._last_maps, self._memory, self._cache_serial, self._cache_maps,
                                          maps, counts)
        self._idle = idle
        self.maps_computed += computed
        return counts[0], counts[1]

    def _load_kernels(self) -> None:
        """Compile (first run) or load from numba's disk cache (~0.3 s) the frame kernels now,
        once per process, rather than inside the first frames() call (a trial's first tick)."""
        global _KERNELS_LOADED
        if _KERNELS_LOADED:
            return
        n = self.skin.n_taxels
        none = np.zeros((0, fk.N_STATE))
        fk.frames_kernel(none, np.zeros(0, np.int64), np.zeros(0), self.rng, *self._tables,
                         self._row_offsets_s, self._gains, self.baseline_counts, np.zeros((2, n, n)),
                         np.zeros((2, n, n)), np.zeros((2, n, n)), np.zeros(2), np.full(1, -1, np.int64),
                         np.zeros((2, n, n)), np.zeros((0, 2, n, n)), np.zeros((2, 0, n, n), np.uint16))
        fk.idle_counts_kernel(np.zeros((2, n, n)), self.rng, self._params, np.zeros((2, 0, n, n), np.uint16))
        _KERNELS_LOADED = True

    def _floor_counts(self) -> np.ndarray:
        """(2, n, n) float counts (before noise and rounding) of the unloaded sheet: zero
        pressure, floor conductance, the same readout arithmetic as the frame kernel."""
        n = self.skin.n_taxels
        g = conductance_layers(self.fsr, np.zeros((1, 2, n, n)), self._gains)
        volts = self.readout.column_volts(g.reshape(-1, n, n)).reshape(-1, 2, n, n)
        return np.ascontiguousarray((self.readout.counts(volts) + self.baseline_counts[None])[0])

    def _idle_frames(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """frames() for unloaded states on an idle sheet: the full pipeline's result (zero
        pressure, floor conductance, constant column voltages), with the same draws from rng."""
        n = self.skin.n_taxels
        counts = np.empty((2, len(t_s), n, n), np.uint16)
        fk.idle_counts_kernel(self._idle_counts, self.rng, self._params, counts)
        self._last_maps[:] = 0.0
        self._memory[0], self._memory[1] = t_s[-1], 1.0
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
