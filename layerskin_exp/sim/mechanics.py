"""Compiled inner loops of the simulated rig's mechanics (numba): actuator motion, the skin
contact with stick-slip friction, and the rod's pose in the skin frame.

The world steps at 1 kHz; in Python each step cost ~20 us, which capped the simulation well
below the speed the protocols need. These kernels run a whole stretch of steps per call. Each
kernel works on a small float64 state vector that its Python owner keeps (LimitedMotion,
StickSlip, SkinModel), so a stretch can be planned, checked and re-run from a saved state; the
Python classes document the physics and hold the parameters.

State layouts (offsets are module constants so the owners and kernels agree):
- motion of d axes: [has_target, stopping, speed, accel, pos (d), vel (d), target (d)]
- friction: [ux, uy, theta, slip_x, slip_y, slip_rad, t_stick, t_stick_rot, slipping]
- contact: [has_prev, prev_t, prev_x, prev_y, prev_yaw, serial, last configuration (11)]
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# ---- motion state ------------------------------------------------------------------------------
M_HAS_TARGET, M_STOPPING, M_SPEED, M_ACCEL, M_POS = 0, 1, 2, 3, 4


def motion_size(d: int) -> int:
    return M_POS + 3 * d


@njit(cache=True, nogil=True)
def _motion_step(st, d, dt, dv):
    """One step of a point under speed and acceleration limits (see kinematics.LimitedMotion);
    dv (d,) is scratch space."""
    has_target = st[M_HAS_TARGET] != 0.0
    if not has_target and st[M_STOPPING] == 0.0:
        return
    p, v, g = M_POS, M_POS + d, M_POS + 2 * d
    a = st[M_ACCEL]
    a_dt = a * dt
    v_now = 0.0
    for i in range(d):
        v_now += st[v + i] * st[v + i]
    v_now = math.sqrt(v_now)
    if not has_target:  # braking to rest
        if v_now <= a_dt:
            for i in range(d):
                st[p + i] += 0.5 * st[v + i] * dt
                st[v + i] = 0.0
            st[M_STOPPING] = 0.0
            return
        scale = (v_now - a_dt) / v_now
        for i in range(d):
            nv = st[v + i] * scale
            st[p + i] += 0.5 * (st[v + i] + nv) * dt
            st[v + i] = nv
        return
    dist = 0.0
    for i in range(d):
        e = st[g + i] - st[p + i]
        dist += e * e
    dist = math.sqrt(dist)
    if dist < 1e-12 or (v_now <= a_dt * (1 + 1e-9) and dist <= 0.5 * (v_now + a_dt) * dt):
        # one step from the target and slow enough to stop inside the acceleration limit: arrive
        for i in range(d):
            st[p + i] = st[g + i]
            st[v + i] = 0.0
        st[M_HAS_TARGET] = 0.0
        return
    # discrete braking curve: after this step (trapezoidal integration) the point must still be
    # able to stop at the target, 0.5 (v + v') dt + v'^2 / (2 a) <= d
    disc = a_dt * a_dt / 4.0 + 2.0 * a * dist - a * v_now * dt
    v_brake = -0.5 * a_dt + math.sqrt(disc) if disc > 0 else 0.0
    v_want = min(st[M_SPEED], max(v_brake, 0.0))
    dv_norm = 0.0
    for i in range(d):
        dv[i] = (st[g + i] - st[p + i]) / dist * v_want - st[v + i]
        dv_norm += dv[i] * dv[i]
    dv_norm = math.sqrt(dv_norm)
    s = a_dt / dv_norm if dv_norm > a_dt else 1.0
    for i in range(d):
        nv = st[v + i] + dv[i] * s
        st[p + i] += 0.5 * (st[v + i] + nv) * dt
        st[v + i] = nv


@njit(cache=True, nogil=True)
def motion_steps(st0, d, dt, m, states_out):
    """Run m steps from state st0 (left unchanged); states_out (m, len(st0)) gets the state after
    each step."""
    st = st0.copy()
    dv = np.empty(d)
    for k in range(m):
        _motion_step(st, d, dt, dv)
        states_out[k, :] = st


# ---- friction and contact ----------------------------------------------------------------------
F_UX, F_UY, F_THETA, F_SLIP_X, F_SLIP_Y, F_SLIP_RAD, F_T_STICK, F_T_STICK_ROT, F_SLIPPING = range(9)
FRICTION_SIZE = 9
C_HAS_PREV, C_PREV_T, C_PREV_X, C_PREV_Y, C_PREV_YAW, C_SERIAL, C_CONFIG = range(7)
CONTACT_SIZE = C_CONFIG + 11

# Columns of a contact step record (SkinModel.step_many's output).
(S_T, S_FX, S_FY, S_FZ, S_TORQUE, S_DELTA, S_CX, S_CY, S_YAW, S_UX, S_UY, S_THETA, S_SLIPPING,
 S_SLIP_X, S_SLIP_Y, S_SLIP_RAD, S_SERIAL) = range(17)
STEP_FIELDS = 17


@njit(cache=True, nogil=True)
def _mu_static(fp, t_stick):
    mu_s, mu_k, aging = fp[0], fp[1], fp[2]
    if aging <= 0.0:
        return mu_s
    return mu_k + (mu_s - mu_k) * (1.0 - math.exp(-t_stick / aging))


@njit(cache=True, nogil=True)
def friction_update(fs, fp, dt, dx, dy, dth, fz, k_t, k_r, radius):
    """One step of the stick-slip contact (see friction.StickSlip). fs: friction state (updated);
    fp: [mu_s, mu_k, aging_s, overshoot]. Returns (Fx, Fy, torque)."""
    if fz <= 0.0:  # no contact: the sheet springs back, nothing sticks
        fs[F_UX] = 0.0
        fs[F_UY] = 0.0
        fs[F_THETA] = 0.0
        fs[F_T_STICK] = 1e9
        fs[F_T_STICK_ROT] = 1e9
        fs[F_SLIPPING] = 0.0
        return 0.0, 0.0, 0.0
    mu_s, mu_k, overshoot = fp[0], fp[1], fp[3]
    rest = max(mu_k - overshoot * (mu_s - mu_k), 0.0)
    slipping = 0.0
    ux, uy = fs[F_UX] + dx, fs[F_UY] + dy
    f = k_t * math.hypot(ux, uy)
    if f > _mu_static(fp, fs[F_T_STICK]) * fz:
        scale = rest * fz / f
        nx, ny = ux * scale, uy * scale
        fs[F_SLIP_X] += nx - ux
        fs[F_SLIP_Y] += ny - uy
        ux, uy = nx, ny
        fs[F_T_STICK] = 0.0
        slipping = 1.0
    else:
        fs[F_T_STICK] += dt
    fs[F_UX], fs[F_UY] = ux, uy
    th = fs[F_THETA] + dth
    tq = k_r * abs(th)
    bound = _mu_static(fp, fs[F_T_STICK_ROT]) * fz * radius
    if tq > bound and tq > 0.0:
        nth = th * rest * fz * radius / tq
        fs[F_SLIP_RAD] += nth - th
        th = nth
        fs[F_T_STICK_ROT] = 0.0
        slipping = 1.0
    else:
        fs[F_T_STICK_ROT] += dt
    fs[F_THETA] = th
    fs[F_SLIPPING] = slipping
    return k_t * ux, k_t * uy, k_r * th


@njit(cache=True, nogil=True)
def chord(cx, cy, yaw, half):
    """Parameters s1 <= 0 <= s2 where the line c + s (cos yaw, sin yaw) leaves the square
    |x|, |y| <= half (0, 0 when it misses)."""
    lo, hi = -1e9, 1e9
    for axis in range(2):
        c = cx if axis == 0 else cy
        d = math.cos(yaw) if axis == 0 else math.sin(yaw)
        if abs(d) < 1e-12:
            if abs(c) > half:
                return 0.0, 0.0
            continue
        a, b = (-half - c) / d, (half - c) / d
        lo, hi = max(lo, min(a, b)), min(hi, max(a, b))
    if hi <= lo:
        return 0.0, 0.0
    return min(lo, 0.0), max(hi, 0.0)


@njit(cache=True, nogil=True)
def _interp(tab, row, dd, i, t, delta, last):
    """Row `row` of the contact tables at indentation delta (grid step dd, bracket i, fraction t);
    linear extrapolation past the last grid point, 0 below the first."""
    if i >= last:
        slope = (tab[row, last] - tab[row, last - 1]) / dd
        return tab[row, last] + slope * (delta - tab[0, last])
    if i < 0:
        return 0.0
    return tab[row, i] + t * (tab[row, i + 1] - tab[row, i])


@njit(cache=True, nogil=True)
def _realised_indentation(tab, d_cmd, length, k_support):
    """Indentation delta of the stack when the indenter is commanded d_cmd into it through a
    series support of stiffness k_support (N/mm; <= 0: rigid): delta + length load(delta)/k = d_cmd."""
    if d_cmd <= 0.0:
        return 0.0
    if k_support <= 0.0:
        return d_cmd
    n = tab.shape[1]
    ks = k_support
    if d_cmd >= tab[0, n - 1] + length * tab[1, n - 1] / ks:
        i = n - 2
    else:
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if tab[0, mid] + length * tab[1, mid] / ks <= d_cmd:
                lo = mid
            else:
                hi = mid
        i = lo
    g0 = tab[0, i] + length * tab[1, i] / ks
    g1 = tab[0, i + 1] + length * tab[1, i + 1] / ks
    t = (d_cmd - g0) / (g1 - g0)
    return tab[0, i] + t * (tab[0, i + 1] - tab[0, i])


@njit(cache=True, nogil=True)
def _series(k_sheet, k_cover):
    """Stiffness of the lattice path (sheet to base) and the cover path (cap to sheet) in series,
    and the share of the cap's elastic travel the sheet makes. A cover with no contact stiffness
    (no table, unloaded) leaves the lattice alone."""
    if k_cover <= 0.0:
        return k_sheet, 1.0
    k = k_sheet * k_cover / (k_sheet + k_cover)
    return k, k / k_sheet


@njit(cache=True, nogil=True)
def contact_steps(rod, tab, geo, fp, cs, fs, t, xyz, yaw, out):
    """Advance the contact through m commanded indenter poses.

    rod: 1 for the rod (line contact), 0 for the hemisphere.
    tab: (7, L) contact tables on one indentation grid: delta, load, shear_extra, torsion_extra,
         friction_radius, cover_shear, cover_torsion (see contact.ContactTables).
    geo: [d_delta, k_support (<= 0 rigid), half width, width^2, k0 * width^2, k0, width^4 / 6].
    fp: friction parameters [mu_s, mu_k, aging_s, overshoot]; cs, fs: contact and friction
    state (updated). t (m,), xyz (m, 3) mm, yaw (m,) rad. out (m, STEP_FIELDS) gets each step.
    """
    dd, k_support, half, width2, k0_area, k0, j_pad0 = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5], geo[6]
    last = tab.shape[1] - 1
    for k in range(t.shape[0]):
        x, y, z, w = xyz[k, 0], xyz[k, 1], xyz[k, 2], yaw[k]
        if rod:
            s1, s2 = chord(x, y, w, half)
            length = s2 - s1
        else:
            s1 = s2 = 0.0
            length = 1.0
        delta = _realised_indentation(tab, -z, length, k_support) if length > 0 else 0.0
        xg = delta / dd
        i = int(xg)
        tg = xg - i
        load = _interp(tab, 1, dd, i, tg, delta, last)
        shear = _interp(tab, 2, dd, i, tg, delta, last)
        fz = max(length * load, 0.0) if delta > 0 else 0.0
        j_pad = j_pad0 + width2 * (x * x + y * y)
        cover = _interp(tab, 5, dd, i, tg, delta, last)
        cover_rot = _interp(tab, 6, dd, i, tg, delta, last)
        if rod:
            i_line = (s2 ** 3 - s1 ** 3) / 3.0
            k_sheet = k0_area + length * shear
            k_sheet_r = k0 * j_pad + shear * i_line
            k_cover, k_cover_r = length * cover, cover_rot * i_line
            radius = (s1 * s1 + s2 * s2) / (2.0 * length) if length > 0 else 0.0
        else:
            k_sheet = k0_area + shear
            k_sheet_r = k0 * j_pad + _interp(tab, 3, dd, i, tg, delta, last)
            k_cover, k_cover_r = cover, cover_rot
            radius = _interp(tab, 4, dd, i, tg, delta, last)
        # the cover (cap -> sheet) in series with the lattice (sheet -> base): the friction state
        # holds the cap's whole elastic travel, the sheet moves by its lattice's share of it
        k_t, share = _series(k_sheet, k_cover)
        k_r, share_r = _series(k_sheet_r, k_cover_r)
        if cs[C_HAS_PREV] == 0.0:
            dt = dx = dy = dw = 0.0
        else:
            dt, dx, dy, dw = t[k] - cs[C_PREV_T], x - cs[C_PREV_X], y - cs[C_PREV_Y], w - cs[C_PREV_YAW]
        cs[C_HAS_PREV], cs[C_PREV_T], cs[C_PREV_X], cs[C_PREV_Y], cs[C_PREV_YAW] = 1.0, t[k], x, y, w
        fx, fy, tq = friction_update(fs, fp, dt, dx, dy, dw, fz, k_t, k_r, radius)
        # a new loading configuration gets a new serial (a hold repeats the last one)
        cfg = (delta, fx, fy, fz, tq, x, y, w, fs[F_UX], fs[F_UY], fs[F_THETA])
        same = True
        for j in range(11):
            if cs[C_CONFIG + j] != cfg[j]:
                same = False
                cs[C_CONFIG + j] = cfg[j]
        if not same:
            cs[C_SERIAL] += 1.0
        o = out[k]
        o[S_T], o[S_FX], o[S_FY], o[S_FZ], o[S_TORQUE], o[S_DELTA] = t[k], fx, fy, fz, tq, delta
        ux, uy, th = share * fs[F_UX], share * fs[F_UY], share_r * fs[F_THETA]
        o[S_CX], o[S_CY], o[S_YAW] = x - ux, y - uy, w
        o[S_UX], o[S_UY], o[S_THETA], o[S_SLIPPING] = ux, uy, th, fs[F_SLIPPING]
        o[S_SLIP_X], o[S_SLIP_Y], o[S_SLIP_RAD], o[S_SERIAL] = fs[F_SLIP_X], fs[F_SLIP_Y], fs[F_SLIP_RAD], cs[C_SERIAL]


# ---- the rod on the grip rig -------------------------------------------------------------------
@njit(cache=True, nogil=True)
def _rotvec_matrix(x, y, z, R):
    """Rodrigues' formula for a rotation vector into R (3, 3)."""
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        for i in range(3):
            for j in range(3):
                R[i, j] = 1.0 if i == j else 0.0
        return
    kx, ky, kz = x / th, y / th, z / th
    c, s = math.cos(th), math.sin(th)
    v = 1.0 - c
    R[0, 0], R[0, 1], R[0, 2] = c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s
    R[1, 0], R[1, 1], R[1, 2] = ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s
    R[2, 0], R[2, 1], R[2, 2] = kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v


@njit(cache=True, nogil=True)
def rod_poses(R_ref, rotvec, p_m, opening_mm, rod_c_m, rod_a, R_tcp_skin, radius_mm, last_yaw, xyz, yaw, R_tcp):
    """The rod in the skin frame for m arm/jaw states (see grip_scene.GripScene.indenter_pose).

    R_ref (3, 3), rotvec (m, 3) relative rotation, p_m (m, 3) TCP position, opening_mm (m,);
    rod_c_m (3,) axis point and rod_a (3,) unit axis in base; R_tcp_skin (3, 3).
    Writes xyz (m, 3) mm, yaw (m,) rad (branch nearest the previous one, starting from
    last_yaw) and R_tcp (m, 3, 3). Returns the last yaw."""
    Rr = np.empty((3, 3))
    for k in range(p_m.shape[0]):
        _rotvec_matrix(rotvec[k, 0], rotvec[k, 1], rotvec[k, 2], Rr)
        Rt = R_ref @ Rr
        R_tcp[k] = Rt
        Rs = Rt @ R_tcp_skin
        # skin origin: TCP + R_tcp (0, -opening/2, 0); everything in skin axes: R_s^T (.)
        half_open_m = -opening_mm[k] / 2.0 * 1e-3
        c = np.empty(3)
        a = np.empty(3)
        for i in range(3):
            origin_i = p_m[k, i] + Rt[i, 1] * half_open_m
            c[i] = rod_c_m[i] - origin_i
        cs = np.empty(3)
        for j in range(3):
            cs[j] = (Rs[0, j] * c[0] + Rs[1, j] * c[1] + Rs[2, j] * c[2]) * 1e3
            a[j] = Rs[0, j] * rod_a[0] + Rs[1, j] * rod_a[1] + Rs[2, j] * rod_a[2]
        ca = cs[0] * a[0] + cs[1] * a[1] + cs[2] * a[2]
        xyz[k, 0] = cs[0] - ca * a[0]
        xyz[k, 1] = cs[1] - ca * a[1]
        xyz[k, 2] = cs[2] - ca * a[2] - radius_mm
        # a rod has no head or tail: keep the branch nearest the last value (continuous through +-90 deg)
        w = math.atan2(a[1], a[0])
        w += math.pi * np.round((last_yaw - w) / math.pi)
        yaw[k] = w
        last_yaw = w
    return last_yaw


@njit(cache=True, nogil=True)
def grip_plan(pos_st, rot_st, jaw_st, dt, m, R_ref, rod_c_m, rod_a, R_tcp_skin, radius_mm, last_yaw, stalled,
              pos_out, rot_out, jaw_out, xyz, yaw, R_tcp, snap):
    """m steps of the grip rig's arm (TCP position, relative rotation vector) and jaw, and the rod
    in the skin frame after each (see grip_scene.GripScene.plan); the states are left unchanged.
    snap (m, 14): TCP position (3), TCP rotation row-major (9), opening, stalled."""
    motion_steps(pos_st, 3, dt, m, pos_out)
    motion_steps(rot_st, 3, dt, m, rot_out)
    motion_steps(jaw_st, 1, dt, m, jaw_out)
    p = pos_out[:, M_POS:M_POS + 3].copy()
    rv = rot_out[:, M_POS:M_POS + 3].copy()
    opening = jaw_out[:, M_POS].copy()
    rod_poses(R_ref, rv, p, opening, rod_c_m, rod_a, R_tcp_skin, radius_mm, last_yaw, xyz, yaw, R_tcp)
    for k in range(m):
        for i in range(3):
            snap[k, i] = p[k, i]
            for j in range(3):
                snap[k, 3 + 3 * i + j] = R_tcp[k, i, j]
        snap[k, 12] = opening[k]
        snap[k, 13] = stalled
