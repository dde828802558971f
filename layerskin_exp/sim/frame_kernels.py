"""Compiled kernels of the simulated skin's frame pipeline (numba, nopython, cached on disk).

One call of `frames_kernel` turns N mechanical states into N frame pairs: pressure at the
quadrature points of each layer (hemisphere: a window around the contact; rod: the full grid),
Gauss-weighted taxel means, each row interpolated to its own sampling instant, FSR hysteresis
and creep, conductance, passive-matrix readout with crosstalk, offsets, noise and rounding.
The physics and its formulas are those documented in `skin.py`, `fsr.py` and `readout.py`;
`SkinModel` only marshals arguments. Random draws (scan jitter, read noise) come from the
model's numpy Generator, drawn inside the kernel (numba runs the Generator's own bit generator
and normal sampler) in the order the vectorised numpy pipeline took them, so a seed gives the
same numbers.

Argument conventions (fixed dtypes, C-contiguous, so each kernel compiles once):
- `states` (N, N_STATE) float64, columns `S_*` (one row per mechanical state);
- `prm`: the parameter record (`PARAMS`, `new_params`): geometry, table grids, FSR and readout
  constants, each by its name;
- `lk` (2, n_pairs, n_fine, 4) float32: per table (the cover's, the superficial core's contact
  half; the lattice's, deep) the profile and its change per unit couple of the shear through the
  cover's lever (per r for the hemisphere, so that times the offset along the couple it gives
  the cos(phi) mode), resampled for nearest-bin lookups, as (profile at row k, row k+1 - row k,
  couple response at row k, its row difference), last column zero (guard);
- `rows` (n_delta, 2) float64: the height of the cover above the deep sensing plane and the
  lattice's height under the contact (mm);
  `bounds` (n_pairs, 2): the cover's and the lattice's reach (mm) beyond which both the profile
  and its couple response stay below WINDOW_EPS of their peaks (the superficial core reads the
  cover's within the first and half the lattice's within the second);
- `dist` (n_dist,) float64 (the tables' grid); `quad` (n*q + q,) float32: quadrature
  coordinates then weights;
  `lattice` (n*q, n*q) float32; `edge` (2, n*q) float32: the lattice's route across a side of
  the pad at the quadrature coordinates (per unit couple per mm along the side; the pad centred
  on the array): the deep sheet's pressure and the lattice's top (`contact.ContactTables`).

Floating point: field values are float32 (as in the numpy pipeline), taxel means, FSR and
readout float64.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.mechanics import chord as _chord

# --- columns of the (N, N_STATE) state matrix
# the leading columns of a mechanics step record (SkinModel.step_many), so records pass as they are
S_T, S_FX, S_FY, S_FZ, S_TORQUE, S_DELTA, S_AX, S_AY, S_YAW, S_UX, S_UY, S_ROT = (
    mk.S_T, mk.S_FX, mk.S_FY, mk.S_FZ, mk.S_TORQUE, mk.S_DELTA, mk.S_CX, mk.S_CY, mk.S_YAW, mk.S_UX, mk.S_UY, mk.S_THETA)
N_STATE = 12
assert (S_T, S_ROT) == (0, N_STATE - 1)

# --- the kernels' parameters: one structured record (fields by name, float64), made by
# `new_params` and filled by `transduction_params` and `SkinModel`; the kernels read `prm.<name>`
PARAMS = np.dtype([
    # geometry: taxels per side, Gauss points per electrode side, rod (1) or hemisphere (0), the
    # first taxel centre, the pitch and half the electrode's side (mm), half the pad's side (mm)
    ("n_taxels", np.float64), ("quad_points", np.float64), ("rod", np.float64), ("first_centre_mm", np.float64),
    ("pitch_mm", np.float64), ("half_electrode_mm", np.float64), ("half_pad_mm", np.float64),
    # how far inside the pad's sides their load's moment acts (ContactTables.side_inset_mm, mm);
    # whether the sheet answers load past the sides as a rigid body (1/0, `_pad_fold`)
    ("side_inset_mm", np.float64), ("fold_sides", np.float64),
    # the contact tables: indentation step and last row index; the fine lookups' origin and scale
    # (superficial, deep: r^2 or signed distance to bin)
    ("delta_step_mm", np.float64), ("last_delta_row", np.float64), ("lk_origin", np.float64), ("lk_scale", np.float64),
    ("lk_origin_deep", np.float64), ("lk_scale_deep", np.float64),
    # the frame: its period (s), whether a hold reuses its maps (1/0), scan jitter (s rms)
    ("frame_period_s", np.float64), ("reuse_maps", np.float64), ("jitter_s", np.float64),
    # the FSR: hysteresis half-width, creep share and time constant (s), saturation (kPa),
    # exponent, floor and saturated conductances (S)
    ("hysteresis", np.float64), ("creep", np.float64), ("creep_s", np.float64), ("saturation_kpa", np.float64),
    ("exponent", np.float64), ("g_floor_s", np.float64), ("g_sat_s", np.float64),
    # the readout: leak and divider conductances (S), mux on-resistance (ohm), supply (V), ADC full
    # scale (counts), crosstalk network on (1/0), read noise (counts rms)
    ("g_leak_s", np.float64), ("g_divider_s", np.float64), ("mux_on_ohm", np.float64), ("supply_v", np.float64),
    ("full_scale", np.float64), ("crosstalk", np.float64), ("noise_counts", np.float64),
])


def new_params() -> np.void:
    """A zeroed parameter record (fields of PARAMS): numba reads it by reference, so a field
    changed in Python is what the next kernel call sees."""
    return np.zeros(1, PARAMS)[0]


# Hemisphere windows: outside, the profile is below this fraction of its peak. At 1e-5 what is
# left out moves a frame's counts by ~1e-4 count on average (one taxel in ~10^4 rounds to a
# neighbouring count against the 1e-8 window; 1e-4 would shift some by several counts).
WINDOW_EPS = 1e-5
_jit = numba.njit(cache=True, error_model="numpy")
_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_FHALF = np.float32(0.5)


def transduction_params(fsr, readout, adc_bits: int | None = None, prm: np.void | None = None) -> np.void:
    """The parameter record (`new_params`) with the FSR and readout fields filled from their
    configs (an FSRConfig and a ReadoutConfig, either may be None); other fields left as in prm."""
    prm = new_params() if prm is None else prm
    if fsr is not None:
        prm["hysteresis"], prm["creep"], prm["creep_s"] = fsr.hysteresis, fsr.creep, fsr.creep_s
        prm["saturation_kpa"], prm["exponent"] = fsr.saturation_kpa, fsr.exponent
        prm["g_floor_s"], prm["g_sat_s"] = 1.0 / (fsr.floor_mohm * 1e6), 1.0 / (fsr.saturated_kohm * 1e3)
    if readout is not None:
        prm["g_leak_s"], prm["g_divider_s"] = 1.0 / (readout.leak_mohm * 1e6), 1.0 / (readout.divider_kohm * 1e3)
        prm["mux_on_ohm"], prm["supply_v"] = readout.mux_on_ohm, readout.supply_v
        prm["crosstalk"] = 1.0 if readout.crosstalk else 0.0
        prm["jitter_s"], prm["noise_counts"] = readout.scan_jitter_ms * 1e-3, readout.noise_counts
    if adc_bits is not None:
        prm["full_scale"] = float(2**adc_bits - 1)
    return prm


# ---------------------------------------------------------------------------------- tables
@_jit
def _delta_row(delta, prm):
    """Indentation row i and fraction t of the contact tables (clipped to the grid)."""
    x = min(max(delta / prm.delta_step_mm, 0.0), prm.last_delta_row)
    i = int(x)
    return i, x - i


@_jit
def _lookup(lk_row, t32, coord, origin32, scale32):
    """Profile and couple response (float32) at coord (r^2 or signed distance, float32) for
    indentation row i + t (lk_row = lk[layer, i], t32 = t): nearest bin of the fine table, linear
    between the two rows; zero beyond the table (guard column)."""
    c = (coord - origin32) * scale32 + _FHALF
    j = min(max(int(c), 0), lk_row.shape[0] - 1)  # branch-free clamp (the guard column is zero)
    return lk_row[j, 1] * t32 + lk_row[j, 0], lk_row[j, 3] * t32 + lk_row[j, 2]


@_jit
def _edge_loads(st, prm, h_lat):
    """The lattice's route of one state: the couple per mm along the pad's sides, as (cx, cy, kk)
    (float32) with cx - kk y across the sides x = +-L at height y and cy + kk x across the sides
    y = +-L at x (N mm / mm).

    The in-plane-stiff sheet hands the lattice the shear as a uniform traction over the pad, plus
    the rotation field (T / J)(-y, x) of a torque (J = (2L)^4 / 6, the square pad's polar
    moment); the lattice's thin sheared layer puts h tau.n on the pad's sides. Its couple: the
    shear's F_t h_L and the torque's T h_L (h_L the lattice's lever). The normal load's own
    moment about the columns' feet, F_z u, is not here: the lattice carries the load straight
    down from where the sheet point under the cap now is (the deep pattern sits at the cap's
    ground position, `frame_fields`)."""
    two_l = 2.0 * prm.half_pad_mm
    mlx = st[S_FX] * h_lat
    mly = st[S_FY] * h_lat
    k = st[S_TORQUE] * h_lat
    # the pair of sides' loads act 2 (L - inset) apart
    kk = k * (two_l - 2.0 * prm.side_inset_mm) / (two_l**4 / 6.0)
    return np.float32(mlx / two_l), np.float32(mly / two_l), np.float32(kk)


@_jit
def _fill_edges(edge, q, half_pad, cx, cy, kk, base, top):
    """base, top (m, m) [y, x] = the lattice's route at every quadrature point (`_edge_loads`):
    its pressure on the deep sheet and its top's on the sheet (signed, before the cell pattern).
    Each pair of sides acts along its own length (|y| <= L for the sides x = +-L)."""
    m = q.shape[0]
    l32 = np.float32(half_pad)
    for r in range(m):
        across_x = cx - kk * q[r] if abs(q[r]) <= l32 else _F0
        eb_r, et_r = edge[0, r], edge[1, r]
        for c in range(m):
            across_y = cy + kk * q[c] if abs(q[c]) <= l32 else _F0
            base[r, c] = edge[0, c] * across_x + eb_r * across_y
            top[r, c] = edge[1, c] * across_x + et_r * across_y


# the grid the load beyond the pad's sides is summed on (`_pad_fold`): cells of about this size,
# their edges on the pad's sides
FOLD_STEP_MM = 0.5


@_jit
def _pad_fold(lk_row, t32, cx, cy, mx32, my32, reach, half_pad, origin32, scale32, out):
    """The rigid-body answer of the sheet to the load its axisymmetric profile about (cx, cy)
    (and couple response times (mx32, my32)) puts beyond the pad's sides, within `reach`:
    out[:] = (a, b, c) of the pressure a + b x + c y (kPa, x and y about the pad's centre) that,
    spread over the pad, carries that load's force and first moments. The tables are solved for
    a pad centred on the contact; on a real pad the sheet rests on the lattice only inside its
    sides, and a sheet whose load would reach past them translates and tilts on the lattice
    instead (its rigid-body modes on a foundation: pressure k (w0 + tx x + ty y)), so that the
    deep layer carries F_z, and its moment, where statics puts them. Zero where the reach stays
    inside the pad. A rigid-body answer needs a sheet whose reach spans the pad: the stretched
    sheet's (large deflection), whose membrane spreads a deep press over all of it. The bending
    plate's influence length, (D / k)^(1/4) = 2-6 mm, is a fraction of the 26 mm pad: near a side
    it answers locally, which a pad-wide tilt is not, so its profile is not folded (`fold_sides`
    off, SkinModel). What that leaves: a 3 N press 2 mm from a side puts 6.5 % of its load past
    it (deep force CoP 0.21 mm inwards); 5 mm or more from the sides, under 1 %."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    L = half_pad
    if abs(cx) + reach <= L and abs(cy) + reach <= L:
        return False
    n_in = max(int(math.ceil(L / FOLD_STEP_MM)), 1)
    h = L / n_in  # cell size: the pad's sides are cell edges
    k0x, k1x = int(math.floor((cx - reach) / h)), int(math.ceil((cx + reach) / h))
    k0y, k1y = int(math.floor((cy - reach) / h)), int(math.ceil((cy + reach) / h))
    r2max = reach * reach
    f = 0.0
    fx = 0.0
    fy = 0.0
    for ky in range(k0y, k1y):
        y = (ky + 0.5) * h
        dy = np.float32(y - cy)
        out_y = abs(y) > L
        for kx in range(k0x, k1x):
            x = (kx + 0.5) * h
            if not out_y and abs(x) <= L:
                continue
            dx = np.float32(x - cx)
            r2 = dx * dx + dy * dy
            if r2 > r2max:
                continue
            v0, v1 = _lookup(lk_row, t32, r2, origin32, scale32)
            v = np.float64(v0 + (mx32 * dx + my32 * dy) * v1)
            f += v
            fx += v * x
            fy += v * y
    two_l = 2.0 * L
    area = h * h
    out[0] = f * area / (two_l * two_l)
    out[1] = fx * area / (two_l**4 / 12.0)
    out[2] = fy * area / (two_l**4 / 12.0)
    return out[0] != 0.0 or out[1] != 0.0 or out[2] != 0.0


@_jit
def _add_fold(field, q, ab):
    """field (m, m) [y, x] += ab[0] + ab[1] x + ab[2] y at the quadrature points."""
    m = q.shape[0]
    a, b, c = np.float32(ab[0]), np.float32(ab[1]), np.float32(ab[2])
    for r in range(m):
        row = a + c * q[r]
        for cc in range(m):
            field[r, cc] += row + b * q[cc]


@_jit
def _window(cx, cy, reach, prm, win, at):
    """Taxel rows/cols [r0, r1] x [c0, c1] (inclusive) whose electrode comes within `reach` of
    (cx, cy), written to win[at:at + 4]; r1 < r0 or c1 < c0 when the reach misses the array."""
    n = int(prm.n_taxels)
    x0, pitch, half_el = prm.first_centre_mm, prm.pitch_mm, prm.half_electrode_mm
    for axis in range(2):
        c = cx if axis == 0 else cy
        lo = math.ceil((c - reach - half_el - x0) / pitch)
        hi = math.floor((c + reach + half_el - x0) / pitch)
        lo = min(max(lo, 0.0), float(n))
        hi = min(max(hi, -1.0), float(n - 1))
        # rows (y) first, then columns (x)
        k = at + (2 if axis == 0 else 0)
        win[k], win[k + 1] = int(lo), int(hi)


# ---------------------------------------------------------------------------------- fields
@_jit
def _disc_pattern(out, also, both, lk, t32, q, cx, cy, mx32, my32, r0, r1, c0, c1, dx2, mdx, origin32, scale32):
    """out (m, m) [y, x] += the lattice's axisymmetric profile about (cx, cy) and its couple
    response times the couple (mx32, my32) . (x - cx, y - cy), over rows [r0, r1) x columns
    [c0, c1); also += the same where both. dx2, mdx (m,): scratch."""
    cx32, cy32 = np.float32(cx), np.float32(cy)
    for c in range(c0, c1):
        dx = q[c] - cx32
        dx2[c] = dx * dx
        mdx[c] = mx32 * dx
    for r in range(r0, r1):
        dy = q[r] - cy32
        dy2 = dy * dy
        mdy = my32 * dy
        for c in range(c0, c1):
            v0, v1 = _lookup(lk, t32, dx2[c] + dy2, origin32, scale32)
            v = v0 + (mdx[c] + mdy) * v1
            out[r, c] += v
            if both:
                also[r, c] += v


@_jit
def _lattice_half(top, r, c0, c1, wa, store, f_sup, colsum):
    """Superficial quadrature row r, columns [c0, c1) beyond the cover's reach: the core reads
    half the lattice top's pressure there (no tension), added to the Gauss-weighted column sums."""
    for c in range(c0, c1):
        v = max(_FHALF * top[r, c], _F0)
        if store:
            f_sup[r, c] = v
        colsum[c] += wa * np.float64(v)


@_jit
def _row_done(colsum, r, c0, c1, quad, n, nq, tax):
    """After quadrature row r: when it closes a taxel row, the Gauss-weighted column sums
    colsum (already weighted by the row weights) become that row's taxel means in tax."""
    if r % nq != nq - 1:
        return
    tr = r // nq
    for tc in range(c0 // nq, c1 // nq):
        s = 0.0
        for b in range(nq):
            s += np.float64(quad[n * nq + b]) * colsum[tc * nq + b]
            colsum[tc * nq + b] = 0.0
        tax[tr, tc] = s


@_jit
def _cells(top, lattice, r0, r1, c0, c1):
    """The lattice top's signed pressure times the cell pattern over rows [r0, r1) x columns
    [c0, c1) (the pattern is the lattice's, in the frame of the sheet it is bonded to)."""
    for r in range(r0, r1):
        for c in range(c0, c1):
            top[r, c] *= lattice[r, c]


@_jit
def _deep_pass(base, top, with_top, lattice, r0, r1, c0, c1, quad, n, nq, store, f_deep, colsum, tax):
    """The lattice's signed pressure on the deep sheet, base (m, m), times the cell pattern over
    rows [r0, r1) x columns [c0, c1): the deep layer reads it (no tension) into f_deep and its
    taxel means; with_top: the lattice top's, top (m, m), gets the pattern over the same range
    (for the superficial core)."""
    m = n * nq
    for r in range(r0, r1):
        wa = np.float64(quad[m + r % nq])
        for c in range(c0, c1):
            cell = lattice[r, c]
            v = max(base[r, c] * cell, _F0)
            if with_top:
                top[r, c] *= cell
            if store:
                f_deep[r, c] = v
            colsum[c] += wa * np.float64(v)
        _row_done(colsum, r, c0, c1, quad, n, nq, tax)


@_jit
def frame_fields(st, prm, lk, rows, bounds, dist, quad, lattice, edge, f_sup, f_deep, tax):
    """Pressure (kPa, float32) at the quadrature points of both layers for one loaded state
    st (N_STATE,), written into f_sup, f_deep (n*q, n*q) [y, x] inside each layer's taxel
    window (hemisphere; the rod's, and with any couple the lattice's route, the whole grid),
    and the Gauss-weighted taxel means (kPa) into tax (2, n, n), zero outside the windows. With
    empty (0, 0) f_sup, f_deep only the taxel means are written (the frame pipeline's path).

    Each layer reads the axisymmetric profile of the loaded laminate plus, along the shear, its
    first-order change under the shear's couple F_t H about the deep plane through the cover's
    lever (lk), and the lattice's route at the pad's sides (`_edge_loads`): the deep layer the
    lattice's pressure on the deep sheet times the cell pattern, the superficial core the mean
    of the cover's (the contact's, lk[0]) and the lattice top's (see contact.py). Neither FSR
    reads tension (the bonded lattice pulls where the sheet lifts), hence the clip at 0.

    Where each pattern sits. The superficial layer's (the cover's and the lattice top's) lies
    about the cap's point in the sheet's frame (S_AX, S_AY), where the superficial taxels are.
    The deep layer's lies about the cap's ground position, that point moved by the sheet's
    travel (S_AX + S_UX, S_AY + S_UY, the cap's position over the deep sheet): the homogenised
    lattice carries the normal load straight down from where it is applied, so the deep force
    CoP meets statics, x_cap + F_x H / F_z (the 3D model of the stack does the same,
    fem_reference.shear3d; the columns' feet, S_AX, would leave the load's moment F_z u to a
    route that does not exist)."""
    n, nq = int(prm.n_taxels), int(prm.quad_points)
    m = n * nq
    q = quad[:m]
    store = f_sup.shape[0] > 0  # the maps path passes empty field arrays: taxel means only
    tax[:, :, :] = 0.0
    colsum = np.zeros(m)
    delta = st[S_DELTA]
    fx, fy = st[S_FX], st[S_FY]
    ax, ay = st[S_AX], st[S_AY]
    # the deep layer's profile about the cap's ground position (see above)
    cdx, cdy = ax + st[S_UX], ay + st[S_UY]
    i, t = _delta_row(delta, prm)
    h_eff = rows[i, 0] * (1 - t) + rows[i + 1, 0] * t
    h_lat = rows[i, 1] * (1 - t) + rows[i + 1, 1] * t
    t32 = np.float32(t)
    origin32, scale32 = np.float32(prm.lk_origin), np.float32(prm.lk_scale)
    scale_d32, origin_d32 = np.float32(prm.lk_scale_deep), np.float32(prm.lk_origin_deep)
    lk_sup, lk_deep = lk[0, i], lk[1, i]
    # the lattice's pressure (signed, before its cell pattern): on the deep sheet (base) and on
    # the sheet (top; they differ by the lattice's route at the pad's sides)
    base = np.zeros((m, m), np.float32)
    top = np.zeros((m, m), np.float32)
    if prm.rod != 0.0:
        _rod_fields(st, prm, lk_sup, lk_deep, h_eff, h_lat, t32, quad, lattice, edge, f_sup, f_deep,
                    origin32, scale32, origin_d32, scale_d32, colsum, tax, bounds[i, 0], bounds[i, 1], base, top)
        return
    win = np.empty(4, np.int64)
    # the lattice's route: at the pad's sides, wherever the contact is
    cx, cy, kk = _edge_loads(st, prm, h_lat)
    edges = cx != _F0 or cy != _F0 or kk != _F0
    if edges:
        _fill_edges(edge, q, prm.half_pad_mm, cx, cy, kk, base, top)
    # the cover's route: the couple of the shear about the deep plane along each axis (N mm), of
    # which the tables' couple response carries the cover's lever
    mx32, my32 = np.float32(fx * h_eff), np.float32(fy * h_eff)
    dx2 = np.empty(m, np.float32)
    mdx = np.empty(m, np.float32)
    # the lattice's top carries the same profile and couple about the cap's point in the sheet's
    # frame: the same points as the base's where the sheet has not travelled (a press)
    same = st[S_UX] == 0.0 and st[S_UY] == 0.0
    # what the profile puts beyond the pad's sides comes back as the sheet's rigid-body pressure
    # over the pad (`_pad_fold`), for the base about the cap's ground position and for the top
    # about its point in the sheet's frame
    if prm.fold_sides != 0.0:  # the bending plate's frames skip this (and its scratch) entirely
        fold = np.empty(3)
        if _pad_fold(lk_deep, t32, cdx, cdy, mx32, my32, bounds[i, 1], prm.half_pad_mm, origin_d32, scale_d32, fold):
            _add_fold(base, q, fold)
            if same:
                _add_fold(top, q, fold)
            edges = True
        if not same and _pad_fold(lk_deep, t32, ax, ay, mx32, my32, bounds[i, 1], prm.half_pad_mm, origin_d32,
                                  scale_d32, fold):
            _add_fold(top, q, fold)
            edges = True
    # deep: the lattice's pressure around the contact's deep-frame position
    _window(cdx, cdy, bounds[i, 1], prm, win, 0)
    r0, r1, c0, c1 = win[0] * nq, (win[1] + 1) * nq, win[2] * nq, (win[3] + 1) * nq
    _disc_pattern(base, top, same, lk_deep, t32, q, cdx, cdy, mx32, my32, r0, r1, c0, c1, dx2, mdx,
                  origin_d32, scale_d32)
    tr0, tr1, tc0, tc1 = r0, r1, c0, c1
    ax32, ay32 = np.float32(ax), np.float32(ay)
    if not same:
        _window(ax, ay, bounds[i, 1], prm, win, 0)
        tr0, tr1, tc0, tc1 = win[0] * nq, (win[1] + 1) * nq, win[2] * nq, (win[3] + 1) * nq
        _disc_pattern(top, top, False, lk_deep, t32, q, ax, ay, mx32, my32, tr0, tr1, tc0, tc1, dx2, mdx,
                      origin_d32, scale_d32)
    if edges:  # the route (or the fold) covers the grid: one pass gives both their cell pattern
        _deep_pass(base, top, True, lattice, 0, m, 0, m, quad, n, nq, store, f_deep, colsum, tax[1])
    else:
        _deep_pass(base, top, same, lattice, r0, r1, c0, c1, quad, n, nq, store, f_deep, colsum, tax[1])
        if not same:
            _cells(top, lattice, tr0, tr1, tc0, tc1)
    # superficial: around the contact, in the superficial frame, over the lattice's window and
    # the cover's (its half of the lattice top's pressure reaches as far as that does); the
    # cover's profile is looked up only in its own, much smaller, window (bounds[i, 0])
    _window(ax, ay, bounds[i, 0], prm, win, 0)
    cr0, cr1, cc0, cc1 = win[0] * nq, (win[1] + 1) * nq, win[2] * nq, (win[3] + 1) * nq
    if edges:
        r0, r1, c0, c1 = 0, m, 0, m
    else:
        _window(ax, ay, max(bounds[i, 0], bounds[i, 1]), prm, win, 0)
        r0, r1, c0, c1 = win[0] * nq, (win[1] + 1) * nq, win[2] * nq, (win[3] + 1) * nq
    for c in range(cc0, cc1):
        dx = q[c] - ax32
        dx2[c] = dx * dx
        mdx[c] = mx32 * dx
    for r in range(r0, r1):
        wa = np.float64(quad[m + r % nq])
        b0, b1 = (cc0, cc1) if cr0 <= r < cr1 and cc1 > cc0 else (c0, c0)
        _lattice_half(top, r, c0, b0, wa, store, f_sup, colsum)
        if b1 > b0:
            dy = q[r] - ay32
            dy2 = dy * dy
            mdy = my32 * dy
            for c in range(b0, b1):
                v0, v1 = _lookup(lk_sup, t32, dx2[c] + dy2, origin32, scale32)
                v = max(_FHALF * (v0 + (mdx[c] + mdy) * v1 + top[r, c]), _F0)
                if store:
                    f_sup[r, c] = v
                colsum[c] += wa * np.float64(v)
        _lattice_half(top, r, max(b1, c0), c1, wa, store, f_sup, colsum)
        _row_done(colsum, r, c0, c1, quad, n, nq, tax[0])


@_jit
def _band(a, b, reach, q, x0):
    """Columns [c0, c1) of the quadrature coordinates q (ascending) where the signed distance
    a (q[c] - x0) + b to a line lies within +-reach (mm); a margin of 1e-3 mm covers float32."""
    reach = reach + 1e-3
    if a == 0.0:
        return (0, q.shape[0]) if abs(b) <= reach else (0, 0)
    lo, hi = x0 + (-reach - b) / a, x0 + (reach - b) / a
    if a < 0.0:
        lo, hi = hi, lo
    return np.searchsorted(q, lo, side="left"), np.searchsorted(q, hi, side="right")


@_jit
def _rod_pattern(out, lk, t32, q, cx, cy, yaw, m0, kt, beta, mid32, reach, origin32, scale32):
    """out (m, m) [y, x] += the lattice's line pattern about the line through (cx, cy) at yaw:
    the profile across it plus the couple (m0 + kt s) times its response, s along the line from
    the point, times the ramp 1 + beta (s - mid) (no lower than 0) of the shear along it."""
    m = q.shape[0]
    ex, ey = np.float32(math.cos(yaw)), np.float32(math.sin(yaw))
    cx32, cy32 = np.float32(cx), np.float32(cy)
    px = np.empty(m, np.float32)
    sx = np.empty(m, np.float32)
    ramp_x = np.empty(m, np.float32)
    for c in range(m):
        dx = q[c] - cx32
        px[c] = -ey * dx
        sx[c] = ex * dx
        ramp_x[c] = _F1 + beta * (ex * dx - mid32)
    for r in range(m):
        dy = q[r] - cy32
        py = ex * dy
        sy = ey * dy
        ramp_y = beta * sy
        b0, b1 = _band(-np.float64(ey), np.float64(py), reach, q, np.float64(cx32))
        for c in range(b0, b1):
            v0, v1 = _lookup(lk, t32, px[c] + py, origin32, scale32)
            ramp = ramp_x[c] + ramp_y
            if ramp < _F0:
                ramp = _F0
            out[r, c] += (v0 + (m0 + kt * (sx[c] + sy)) * v1) * ramp


@_jit
def _rod_fields(st, prm, lk_sup, lk_deep, h_eff, h_lat, t32, quad, lattice, edge, f_sup, f_deep,
                origin32, scale32, origin_d32, scale_d32, colsum, tax, reach_cover, reach_deep, base, top):
    """Rod line load on the quadrature grid, both layers [y, x] (float32), and taxel means. Each
    quadrature row looks the profiles up on the band of columns within reach_cover (the cover's
    profile) or reach_deep (the lattice's) of the line (beyond, the profile is below WINDOW_EPS
    of its peak); base, top (m, m) zero or holding nothing yet, scratch for the lattice's pressure.

    The superficial patterns (the cover's, the lattice top's) lie about the cap's line in the
    sheet's frame, the deep one about the cap's line over the deep sheet: its point moved by the
    sheet's travel and its axis at the rod's own yaw, not turned with the sheet (as frame_fields:
    the lattice carries the load straight down). Across the line, per unit length, the shear's
    couple F_perp H adds the couple response (the cover's lever, contact.ContactTables). The
    twist enters the same way, strip by strip along the line: torsion loads the line with the
    traction T s / I_s (s along the line from the contact point, I_s = int s^2 ds), a couple
    T H s / I_s per unit length. Along the line, the cover's lever of the shear is balanced by a
    linear load gradient along it. The lattice's route (`_edge_loads`: the shear's F_t h_L, the
    torque's T h_L) lies at the pad's sides."""
    n, nq = int(prm.n_taxels), int(prm.quad_points)
    m = n * nq
    q = quad[:m]
    store = f_sup.shape[0] > 0
    fz, fx, fy = st[S_FZ], st[S_FX], st[S_FY]
    yaw_s = st[S_YAW] - st[S_ROT]  # the rod's axis in the sheet's frame
    cdx, cdy = st[S_AX], st[S_AY]  # the cap's point in the sheet's frame
    s1, s2 = _chord(cdx, cdy, yaw_s, prm.half_pad_mm)
    length = max(s2 - s1, 1e-9)
    line_q = fz / length  # N/mm
    ex, ey = np.float32(math.cos(yaw_s)), np.float32(math.sin(yaw_s))
    ex64, ey64 = np.float64(ex), np.float64(ey)
    i_s = (s2**3 - s1**3) / 3.0
    cx, cy, kk = _edge_loads(st, prm, h_lat)
    edges = cx != _F0 or cy != _F0 or kk != _F0
    if edges:
        _fill_edges(edge, q, prm.half_pad_mm, cx, cy, kk, base, top)
    # per unit length across the line (its normal (-ey, ex)): the shear's couple at the contact
    # point, and the torque's growth per mm along the line
    m0 = np.float32((-fx * ey64 + fy * ex64) * h_eff / length)
    kt = np.float32(st[S_TORQUE] * h_eff / i_s)
    # along the line: the cover's lever of the shear, balanced by a linear load gradient
    mid32 = np.float32(0.5 * (s1 + s2))
    beta = np.float32((fx * ex64 + fy * ey64) * (h_eff - h_lat) / (line_q * length**3 / 12.0))
    # the lattice top about the line in the sheet's frame, its base about the line over the deep
    # sheet (the same line where the sheet has neither travelled nor turned)
    _rod_pattern(top, lk_deep, t32, q, cdx, cdy, yaw_s, m0, kt, beta, mid32, reach_deep, origin_d32, scale_d32)
    if st[S_UX] == 0.0 and st[S_UY] == 0.0 and st[S_ROT] == 0.0 and not edges:
        base += top  # base held nothing yet
    else:
        _rod_pattern(base, lk_deep, t32, q, cdx + st[S_UX], cdy + st[S_UY], st[S_YAW], m0, kt, beta, mid32,
                     reach_deep, origin_d32, scale_d32)
    cdx32, cdy32 = np.float32(cdx), np.float32(cdy)
    px = np.empty(m, np.float32)  # across-line coordinate, column part
    sx = np.empty(m, np.float32)  # along-line coordinate, column part
    for c in range(m):
        dx = q[c] - cdx32
        px[c] = -ey * dx
        sx[c] = ex * dx
    _deep_pass(base, top, True, lattice, 0, m, 0, m, quad, n, nq, store, f_deep, colsum, tax[1])
    for r in range(m):
        dy = q[r] - cdy32
        py = ex * dy
        sy = ey * dy
        wa = np.float64(quad[m + r % nq])
        # the cover's band about the line (its profile looked up there only); elsewhere the
        # superficial core reads half the lattice top's pressure
        b0, b1 = _band(-ey64, np.float64(py), reach_cover, q, np.float64(cdx32))
        _lattice_half(top, r, 0, b0, wa, store, f_sup, colsum)
        for c in range(b0, b1):
            along = sx[c] + sy
            v0, v1 = _lookup(lk_sup, t32, px[c] + py, origin32, scale32)
            v = max(_FHALF * (v0 + (m0 + kt * along) * v1 + top[r, c]), _F0)
            if store:
                f_sup[r, c] = v
            colsum[c] += wa * np.float64(v)
        _lattice_half(top, r, max(b1, 0), m, wa, store, f_sup, colsum)
        _row_done(colsum, r, 0, m, quad, n, nq, tax[0])


@_jit
def maps_kernel(states, serial, prm, lk, rows, bounds, dist, quad, lattice, edge, cache_serial, cache_maps, maps):
    """Taxel-mean pressure maps (N, 2, n, n) of N states into maps (zero when unloaded). A
    state whose config serial (>= 0) equals the previous one's (or, for the first,
    cache_serial[0]) repeats its loading configuration and reuses its maps (holds), unless
    prm.reuse_maps is 0. Updates the cache (the last state's serial and maps). Returns how many
    states' maps were computed."""
    f_sup = np.empty((0, 0), np.float32)  # fields are not kept: taxel means only
    f_deep = np.empty((0, 0), np.float32)
    reuse = prm.reuse_maps != 0.0
    prev = cache_serial[0]
    computed = 0
    for k in range(states.shape[0]):
        s = serial[k]
        if reuse and s >= 0 and s == prev:
            if k == 0:
                maps[0] = cache_maps
            else:
                maps[k] = maps[k - 1]
        else:
            if states[k, S_FZ] > 0.0:
                frame_fields(states[k], prm, lk, rows, bounds, dist, quad, lattice, edge, f_sup, f_deep, maps[k])
            else:
                maps[k] = 0.0
            computed += 1
        prev = s
    n_all = states.shape[0]
    if n_all:
        cache_serial[0] = serial[n_all - 1]
        cache_maps[:] = maps[n_all - 1]
    return computed


@_jit
def fields_kernel(states, prm, lk, rows, bounds, dist, quad, lattice, edge, out_sup, out_deep):
    """Pressure (kPa, float32) at the quadrature points of N states into out_sup, out_deep
    (N, n*q, n*q), zero-initialised by the caller; only each layer's window is written."""
    n = int(prm.n_taxels)
    tax = np.empty((2, n, n))
    for k in range(states.shape[0]):
        if states[k, S_FZ] > 0.0:
            frame_fields(states[k], prm, lk, rows, bounds, dist, quad, lattice, edge, out_sup[k], out_deep[k], tax)


# ---------------------------------------------------------------------------------- transduction
@_jit
def _fsr_row(now, before, w, play, lag, alpha, w_h, c_cr, eff):
    """One sample of the FSR memories along a taxel row (n,): the play operator (hysteresis,
    half-width w_h of the input) and a first-order creep lag (alpha = 1 - exp(-dt / tau)),
    mixed as (1 - c_cr) play + c_cr lag into the effective pressure eff. The row is sampled at
    its own instant: pressure interpolated between this frame's map (now) and the previous
    frame's (before) with weight w on before. play, lag updated in place. (Branch-free, so
    the loop vectorises.)"""
    for c in range(now.shape[0]):
        p = max(now[c] * (1 - w) + before[c] * w, 0.0)
        pl = min(max(play[c], p * (1.0 - w_h)), p * (1.0 + w_h))
        lg = lag[c] + alpha * (pl - lag[c])
        play[c], lag[c] = pl, lg
        eff[c] = (1.0 - c_cr) * pl + c_cr * lg


@_jit
def _conductance(p_kpa, gain, prm):
    """gain (G_floor + G_sat x / (1 + x)), x = (p / p_sat)^n for p > 0 (siemens).

    The power runs in float32 (powf: a quarter of pow's cost here, relative error ~1e-7);
    below 1e-30 x^n (n > 0 ... < 1e-30) cannot change G_floor + G_sat x / (1 + x) in float64."""
    x = 0.0
    if p_kpa > 0.0:
        y = np.float32(p_kpa / prm.saturation_kpa)
        if y > np.float32(1e-30):
            x = np.float64(y ** np.float32(prm.exponent))
    return gain * (x * prm.g_sat_s / (1.0 + x) + prm.g_floor_s)


@_jit
def fsr_advance_kernel(pressure, dt_s, play, lag, hysteresis, creep, creep_s, eff):
    """Hysteresis and creep over N successive samples: pressure (N, L, a, b) (kPa), dt_s (N,)
    seconds since the previous sample; play, lag (L, a, b) memories updated in place; eff
    (N, L, a, b) receives the effective pressure."""
    for k in range(pressure.shape[0]):
        alpha = 1.0 - math.exp(-max(dt_s[k], 0.0) / creep_s)
        for li in range(pressure.shape[1]):
            for r in range(pressure.shape[2]):
                row = pressure[k, li, r]
                _fsr_row(row, row, 0.0, play[li, r], lag[li, r], alpha, hysteresis, creep, eff[k, li, r])


@_jit
def conductance_kernel(pressure, gain, prm, out):
    """Static conductance (siemens) out (N, L, a, b) of pressure (N, L, a, b), gains (L, a, b)."""
    for k in range(pressure.shape[0]):
        for li in range(pressure.shape[1]):
            for r in range(pressure.shape[2]):
                for col in range(pressure.shape[3]):
                    out[k, li, r, col] = _conductance(pressure[k, li, r, col], gain[li, r, col], prm)


@numba.njit(cache=True, error_model="numpy", fastmath=True)
def _column_volts(g, prm, y, chol, vec, out):
    """Column voltages out (n, n) [driven row, column] of one layer with crosstalk, for
    conductances g (n, n) [row, column] (siemens).

    Nodal analysis over rows and columns; eliminating the column nodes leaves the symmetric
    positive-definite row Schur complement S = D_r - G D_c^-1 G^T, and with Z = S^-1 driving
    row i through g_on reads V = Vs g_on (Z G D_c^-1)[i, :] / (1 + g_on Z_ii) (Sherman-Morrison
    on the source branch) = Vs X[i, :] / (r_on + Z_ii), X = Z G D_c^-1. S = L L^T (Cholesky,
    in place), X by forward and back substitution; Z S = I gives
    Z D_r = I + X D_c (G D_c^-1)^T, so Z_ii = (1 + sum_c X_ic g_ic) / d_r,i.
    (numba's np.linalg.solve / inv / cholesky cost 6 / 3 / 0.7 us per 16x16 system here in
    allocation and LAPACK call overhead, eight systems per 4-frame call; this, about 2 us.)
    Scratch (float64, C-contiguous): y (n, n), chol (n, n), vec (2, n).
    """
    n = g.shape[0]
    d_c, d_r = vec[0], vec[1]
    for c in range(n):
        d_c[c] = prm.g_divider_s
    for r in range(n):
        s = prm.g_leak_s
        for c in range(n):
            s += g[r, c]
            d_c[c] += g[r, c]
        d_r[r] = s
    for r in range(n):  # y = G D_c^-1
        for c in range(n):
            y[r, c] = g[r, c] / d_c[c]
    for r in range(n):  # S, lower triangle
        for k in range(r + 1):
            s = 0.0
            for c in range(n):
                s += y[r, c] * g[k, c]
            chol[r, k] = -s
        chol[r, r] += d_r[r]
    for j in range(n):  # Cholesky factor L, in place
        s = chol[j, j]
        for p in range(j):
            s -= chol[j, p] * chol[j, p]
        ljj = math.sqrt(s)
        chol[j, j] = ljj
        for i in range(j + 1, n):
            s = chol[i, j]
            for p in range(j):
                s -= chol[i, p] * chol[j, p]
            chol[i, j] = s / ljj
    for r in range(n):  # forward: y <- L^-1 y
        for p in range(r):
            lrp = chol[r, p]
            for c in range(n):
                y[r, c] -= lrp * y[p, c]
        inv = 1.0 / chol[r, r]
        for c in range(n):
            y[r, c] *= inv
    for r in range(n - 1, -1, -1):  # back: y <- L^-T y = X
        for p in range(r + 1, n):
            lpr = chol[p, r]
            for c in range(n):
                y[r, c] -= lpr * y[p, c]
        inv = 1.0 / chol[r, r]
        for c in range(n):
            y[r, c] *= inv
    vs, r_on = prm.supply_v, prm.mux_on_ohm
    for r in range(n):
        s = 1.0
        for c in range(n):
            s += y[r, c] * g[r, c]
        f = vs / (r_on + s / d_r[r])  # Vs / (r_on + Z_ii)
        for c in range(n):
            out[r, c] = f * y[r, c]


@_jit
def column_volts_batch(g, prm, out):
    """Column voltages out (M, n, n) [driven row, column] of M layers with conductances
    g (M, n, n) (siemens): the crosstalk network (`_column_volts`), or without crosstalk each
    taxel alone in series with the mux and its divider."""
    n_mat, n = g.shape[0], g.shape[1]
    vs, r_on = prm.supply_v, prm.mux_on_ohm
    if prm.crosstalk == 0.0:
        r_div = 1.0 / prm.g_divider_s
        for m in range(n_mat):
            for r in range(n):
                for c in range(n):
                    out[m, r, c] = vs * r_div / (r_on + 1.0 / g[m, r, c] + r_div)
        return
    y, chol, vec = np.empty((n, n)), np.empty((n, n)), np.empty((2, n))
    for m in range(n_mat):
        _column_volts(g[m], prm, y, chol, vec, out[m])


# ---------------------------------------------------------------------------------- frames
@_jit
def frames_kernel(states, serial, t_s, rng, prm, lk, rows, bounds, dist, quad, lattice, edge,
                  row_offsets, gains, baseline, play, lag, last_maps, memory, cache_serial, cache_maps,
                  maps, counts):
    """N frame pairs: counts (2, N, n, n) uint16 for states (N, N_STATE) completed at t_s (N,).

    serial (N,) int64: configuration serials (-1: unknown) for the maps reuse during holds;
    rng: the numpy Generator of the random draws, standard normals taken in this order: the
    scan jitter (N, 2, n) (times prm.jitter_s seconds added to each row's sampling instant)
    if prm.jitter_s > 0, then the read noise (2, N, n, n) (times prm.noise_counts
    counts) if that is > 0 (`_read_noise`);
    row_offsets (2, n) seconds from each row's nominal instant to the frame end;
    gains, baseline (2, n, n); play, lag, last_maps (2, n, n) updated in place;
    memory (2,) float64 [time of the last frame, whether there was one] updated in place;
    cache_serial (1,), cache_maps (2, n, n): the maps reuse cache (see `maps_kernel`);
    maps (N, 2, n, n) scratch, receives the maps. Returns (whether the sheet is idle
    afterwards: no pressure at the last frame and both FSR memories zero, maps computed).
    """
    n_all = states.shape[0]
    if n_all == 0:
        return True, 0
    n = int(prm.n_taxels)
    computed = maps_kernel(states, serial, prm, lk, rows, bounds, dist, quad, lattice, edge, cache_serial,
                           cache_maps, maps)
    sj = prm.jitter_s
    w_h, c_cr, creep_s = prm.hysteresis, prm.creep, prm.creep_s
    g = np.empty((n_all * 2, n, n))  # conductance [frame * 2 + layer]
    eff_row = np.empty(n)
    prev_t = memory[0] if memory[1] != 0.0 else t_s[0] - prm.frame_period_s
    for k in range(n_all):
        tk = t_s[k]
        dt = tk - prev_t  # time since the previous frame
        span = max(dt, 1e-9)
        alpha = 1.0 - math.exp(-max(dt, 0.0) / creep_s)
        if k > 0:
            before = maps[k - 1]
        elif memory[1] != 0.0:
            before = last_maps
        else:
            before = maps[0]
        for layer in range(2):
            for r in range(n):
                row_t = tk - row_offsets[layer, r]
                if sj > 0.0:
                    row_t = row_t + sj * rng.standard_normal()
                w = min(max((tk - row_t) / span, 0.0), 1.0)
                _fsr_row(maps[k, layer, r], before[layer, r], w, play[layer, r], lag[layer, r], alpha, w_h, c_cr,
                         eff_row)
                for c in range(n):
                    g[2 * k + layer, r, c] = _conductance(eff_row[c], gains[layer, r, c], prm)
        prev_t = tk
    volts = np.empty_like(g)
    column_volts_batch(g, prm, volts)
    fs, vs = prm.full_scale, prm.supply_v
    values = g.reshape((2, n_all, n, n))  # the conductances are spent: their memory takes the counts
    for layer in range(2):
        for k in range(n_all):
            for r in range(n):
                for c in range(n):
                    values[layer, k, r, c] = volts[2 * k + layer, r, c] / vs * fs + baseline[layer, r, c]
    _read_noise(values, rng, prm, counts)
    if n_all:
        last_maps[:] = maps[n_all - 1]
        memory[0], memory[1] = t_s[n_all - 1], 1.0
    idle = True
    for layer in range(2):
        for r in range(n):
            for c in range(n):
                if last_maps[layer, r, c] != 0.0 or play[layer, r, c] != 0.0 or lag[layer, r, c] != 0.0:
                    idle = False
    return idle, computed


@_jit
def _read_noise(values, rng, prm, counts):
    """counts (2, N, n, n) uint16: float counts values (2, N, n, n) plus the read noise
    (prm.noise_counts rms; standard normals from rng in the arrays' order), rounded and
    clipped to [0, full scale]."""
    sn, fs = prm.noise_counts, prm.full_scale
    src, dst = values.reshape(-1), counts.reshape(-1)
    for i in range(src.shape[0]):
        v = src[i]
        if sn > 0.0:
            v += sn * rng.standard_normal()
        dst[i] = np.uint16(min(max(np.rint(v), 0.0), fs))


@_jit
def idle_counts_kernel(idle_counts, rng, prm, counts):
    """Counts (2, N, n, n) of an idle sheet: constant float counts (2, n, n) plus the read
    noise, rounded and clipped to [0, full scale]. Takes the draws `frames_kernel` would (the
    scan jitter's too, unused at zero pressure, so a seed gives the same noise either way)."""
    n_all, n = counts.shape[1], counts.shape[2]
    if prm.jitter_s > 0.0:
        for _ in range(n_all * 2 * n):
            rng.standard_normal()
    values = np.empty(counts.shape)
    for layer in range(2):
        for k in range(n_all):
            values[layer, k] = idle_counts[layer]
    _read_noise(values, rng, prm, counts)
