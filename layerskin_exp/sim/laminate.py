"""The superficial laminate on the lattice: a plate on a nonlinear foundation, pressed by a
rigid indenter through the cover.

The cover and the superficial FSR sheet (two copper-on-polyimide films with the Velostat
between them) are a thin plate of bending rigidity D. It rests on the spacer lattice, whose
columns carry the pressure of their own compression p_f(w) (`spacer.SpacerLaw`, bonded to the
sheet, so it also pulls back where the sheet lifts) and whose walls couple neighbouring
columns in shear (Pasternak/Vlasov, G_p = G_lattice h / 3). The indenter presses the plate
through the cover, a thin bonded rubber layer of stiffness k_c per area. In the plate's
deflection w (mm, positive down, = the lattice's compression):

    D lap^2 w - G_p lap w + p_f(w) = p_c,   p_c = k_c max(delta - z_ind - w, 0)

with delta the indenter's depth below the undeformed cover and z_ind(r) the height of its
surface above its lowest point. The plate spreads the load: the contact and the loaded
region grow with the load, and the lattice under the contact densifies only once the sheet's
bending can no longer hand the load outwards. Beyond the pad the plate ends (a free edge).

The sheet sinks by many times its own thickness (1.7 mm at 3 N against 0.19 mm), so for the
hemisphere it bends as a plate in large deflection (von Karman): it also stretches, with
membrane strains e_r = u' + w'^2 / 2, e_theta = u / r (u its radial displacement) and forces
N = C (e + nu e_other), C the films' and core's tension stiffness per width
(`sheet_membrane_n_per_mm`); the membrane's term -(1/r)(r N_r w')' joins the plate's equation
and (r N_r)' = N_theta holds in the sheet's plane. Even with the pad's edge free (N_r = 0
there) a dish-shaped sheet pulls its centre taut and squeezes its outer ring in hoop, which
hands the load outwards further than bending alone (the 3D half-model's sheet carries more
than half of 3 N this way, `fem_reference.shear3d`). A line contact bends the sheet into a
cylinder whose free sides carry no membrane force, so the rod's plate stays linear.

D is a field that follows the loaded state: the electrode films are held to the Velostat by
friction only (`FrictionInterface`), so the sheet bends as a sandwich where friction can carry
the sandwich's shear flow (the contact's centre, where the pressure is high and the flow small)
and as loose films elsewhere. Each equilibrium is solved for a fixed field, the field updated
from the solved pressures, and the two iterated until the field settles.

Two geometries, both on a uniform grid from the contact outwards:
- "hemisphere": axisymmetric about the contact (the square pad replaced by the disc of the same
  area), lap w = (1/r) (r w')';
- "rod": a line contact, cylindrical bending across the rod axis, per unit length along it.

This module is the readable reference: it is run once per design to build the contact tables
(`contact.build_tables`), so it stays in numpy/scipy. Lengths mm, pressures N/mm^2 inside the
solver (kPa at its interface), forces N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from layerskin_exp.sim.spacer import SpacerLaw

KPA = 1e-3  # N/mm^2 per kPa
SHEET_POISSON = 0.34  # the films' polyimide (the sheet is taken as isotropic in its plane)
# How fast a bonded layer's end effect dies away from a free side, as Re(lambda) h: the
# eigenfunctions of a strip clamped on both faces decay as exp(-lambda s), s in from the side,
# with w = lambda h the roots of (3 - 4 nu) sin w + w = 0 (plane strain). The slowest root has
# Re w = 4.21 for nu = 0.5 (the Papkovich-Fadle value), 4.33 for nu = 0.3 and 4.42 for nu = 0; the
# lattice's homogenised Poisson's ratio lies in that range, so its end effect reaches
# h / 4.21 (the longest of these) inside the pad's side.
END_DECAY = 4.21


def edge_fade_mm(lattice_height_mm: float) -> float:
    """Distance (mm) over which the lattice's shear traction fades to zero inside the pad's free
    side (`END_DECAY`); the side's load is centred this far inside it."""
    return lattice_height_mm / END_DECAY


def laplacian(kind: str, n: int, step_mm: float) -> sp.csr_matrix:
    """Second-order finite-difference Laplacian on n points from the contact outwards.

    hemisphere: r_j = j step, lap w = (1/r)(r w')' with the symmetry condition at r = 0
    (lap w = 2 w'' there); rod: d_j = (j - (n-1)/2) step, lap w = w''. The last point(s) carry
    w = 0 far beyond the pad (the plate there is cut free by its zero rigidity)."""
    h2 = step_mm * step_mm
    main = np.empty(n)
    lo = np.empty(n - 1)
    up = np.empty(n - 1)
    if kind == "hemisphere":
        main[0], up[0] = -4.0 / h2, 4.0 / h2
        j = np.arange(1, n)
        r = j * step_mm
        rp, rm = r + 0.5 * step_mm, r - 0.5 * step_mm
        main[1:] = -(rp + rm) / (r * h2)
        lo[:] = rm / (r * h2)
        up[1:] = (rp / (r * h2))[:-1]
    else:
        main[:], lo[:], up[:] = -2.0 / h2, 1.0 / h2, 1.0 / h2
    return sp.diags([lo, main, up], [-1, 0, 1], format="csr")


def laplacian_m1(n: int, step_mm: float) -> sp.csr_matrix:
    """Laplacian of the first angular mode w(r) cos(phi) on r_j = j step: (1/r)(r w')' - w / r^2,
    with w(0) = 0 (the mode vanishes on the axis; row 0 only keeps the system regular)."""
    h2 = step_mm * step_mm
    r = np.arange(n) * step_mm
    main = np.empty(n)
    lo = np.zeros(n - 1)
    up = np.zeros(n - 1)
    main[0] = 1.0
    rj = r[1:]
    rp, rm = rj + 0.5 * step_mm, rj - 0.5 * step_mm
    main[1:] = -(rp + rm) / (rj * h2) - 1.0 / rj**2
    lo[1:] = (rm / (rj * h2))[1:]  # the coupling to w_0 = 0 is dropped
    up[1:] = (rp / (rj * h2))[:-1]
    return sp.diags([lo, main, up], [-1, 0, 1], format="csr")


@dataclass
class LaminateSolution:
    """The loaded laminate at one indentation: deflection, contact and foundation pressure."""

    delta_mm: float
    w_mm: np.ndarray  # (n,) deflection of the sheet = compression of the lattice
    contact_kpa: np.ndarray  # (n,) pressure between indenter and cover
    foundation_kpa: np.ndarray  # (n,) pressure the lattice carries (negative: pulling the sheet)
    iterations: int
    rigidity_n_mm: np.ndarray | None = None  # (n,) the sheet's bending rigidity at this state
    composite: np.ndarray | None = None  # (n,) degree of sandwich action (1 bonded .. 0 slipping)
    u_mm: np.ndarray | None = None  # (n,) the sheet's radial displacement (large deflection only)
    # (n - 1,) radial and hoop membrane forces N_r, N_theta (N/mm) between neighbouring grid points
    membrane_n_per_mm: tuple[np.ndarray, np.ndarray] | None = None


@dataclass
class FrictionInterface:
    """The electrode films held to the Velostat by friction only (they must touch it to conduct).

    A sandwich needs its interfaces to carry the core's shear flow tau = Q / d (Q the sheet's
    transverse shear force per width, d the distance between the films); friction carries at
    most mu p, p the pressure clamping the films to the core. Where mu p >= tau the films stick
    and the sheet bends as the sandwich; where it is less they slide, carrying mu p, and only
    that fraction of the sandwich action survives (a rigid-plastic shear connection, the
    partial-interaction reading of a composite beam). Locally the rigidity is
    D = D_own + eta (D_sandwich - D_own), eta = min(1, mu p / tau)."""

    own_n_mm: float  # films and core bending on their own
    sandwich_n_mm: float  # the fully bonded sandwich
    separation_mm: float  # d, between the films' mid-planes
    friction: float  # film-Velostat friction coefficient


@dataclass
class CoupleResponse:
    """First-order response of the loaded laminate to the shear's moment, per unit couple.

    The traction on the cover (resultant F_t, taken proportional to the contact pressure, as
    when the contact slides) acts at height H above the deep sensing plane: about that plane it
    is a couple F_t H, which the cover hands to the sheet under the contact
    (`PlateOnFoundation.couple`) and the sheet to the lattice over the whole pad, whose moment
    ends at the pad's edge (`PlateOnFoundation.edge_couple`). The sheet's antisymmetric
    deflection w1 cos(phi) (hemisphere; odd across the rod) changes the lattice pressure by
    k_f(r) w1 (k_f its tangent stiffness at the loaded state) and the contact pressure by
    -k_c w1 where the cover touches the indenter (the indenter is held by the stage and takes
    part of the moment). Amplitudes are per N mm of couple (hemisphere) or per N mm/mm (rod).
    """

    w_mm: np.ndarray  # (n,) deflection amplitude, mm per N mm
    contact_kpa: np.ndarray  # (n,) contact pressure amplitude
    foundation_kpa: np.ndarray  # (n,) lattice pressure amplitude on the deep sheet
    # the part of foundation_kpa the lattice hands straight to the deep sheet (half the edge
    # term of its moment, `PlateOnFoundation.edge_couple`): its top, under the sheet, has it with
    # the other sign, so the lattice presses the sheet with foundation_kpa - 2 direct_kpa
    direct_kpa: np.ndarray | None = None


class PlateOnFoundation:
    """Plate (the cover + superficial sheet) on the lattice foundation under a rigid indenter.

    kind: "hemisphere" (axisymmetric) or "rod" (line contact). `rigidity_n_mm` D, `pasternak_n_per_mm`
    G_p, `cover_n_per_mm3` k_c (compression) and `cover_shear_n_per_mm3` G_c / t_c (shear); `law` the lattice's compression law; `pad_radius_mm` where the
    plate ends (hemisphere: radius of the disc of the pad's area; rod: half the pad width);
    `rim_mm` the width of the pad's solid rim inside that edge (`SpacerConfig.rim_width_mm`; 0: the
    lattice runs out to the side). The rim is bonded solid silicone: a linear foundation of
    E_s / (1 - nu^2) / h (a strip long along the side, free across it: plane strain), about
    three times the open lattice's E_lat / h, and 2 / rho times the lattice's shear modulus.
    """

    def __init__(self, kind: str, law: SpacerLaw, rigidity_n_mm: float, pasternak_n_per_mm: float,
                 cover_n_per_mm3: float, indenter_radius_mm: float, pad_radius_mm: float,
                 step_mm: float = 0.05, interface: FrictionInterface | None = None,
                 cover_shear_n_per_mm3: float = 0.0, rim_mm: float = 0.0, membrane_n_per_mm: float = 0.0,
                 poisson: float = SHEET_POISSON, wrinkle_n_per_mm: float | None = None):
        if kind not in ("hemisphere", "rod"):
            raise ValueError(f"kind={kind!r}: must be 'hemisphere' or 'rod'")
        self.kind, self.law = kind, law
        self.rigidity, self.pasternak, self.k_cover = rigidity_n_mm, pasternak_n_per_mm, cover_n_per_mm3
        self.cover_shear_n_per_mm3 = cover_shear_n_per_mm3
        self.interface = interface
        self.radius = indenter_radius_mm
        self.step = step_mm
        reach = pad_radius_mm + 3.0  # a free margin beyond the edge, where nothing carries load
        if kind == "hemisphere":
            n = int(round(reach / step_mm)) + 1
            self.x = np.arange(n) * step_mm
            self.area = 2.0 * np.pi * self.x * step_mm  # ring areas
            self.area[0] = np.pi * (0.5 * step_mm) ** 2
        else:
            half = int(round(reach / step_mm))
            self.x = (np.arange(2 * half + 1) - half) * step_mm
            self.area = np.full(self.x.shape, step_mm)  # per mm of rod length
        on_pad = np.abs(self.x) <= pad_radius_mm
        self.on_pad, self.pad_radius = on_pad, pad_radius_mm
        if not 0.0 <= rim_mm < pad_radius_mm:
            raise ValueError(f"rim_mm={rim_mm!r}: the solid rim's width must lie in [0, {pad_radius_mm}) mm")
        self.rim_mm = rim_mm
        self.rim = on_pad & (np.abs(self.x) > pad_radius_mm - rim_mm) if rim_mm > 0 else np.zeros(len(self.x), bool)
        cfg = law.cfg
        self._k_rim = cfg.modulus_kpa / (1.0 - cfg.poisson**2) * KPA / law.h_mm
        self._lap = laplacian(kind, len(self.x), step_mm)
        self._lap1 = laplacian_m1(len(self.x), step_mm) if kind == "hemisphere" else self._lap
        self.z_ind = self.indenter_height(self.x)
        self._gp = np.where(on_pad, pasternak_n_per_mm, 0.0)
        self._linear, self._linear1 = self._operators(np.full(len(self.x), rigidity_n_mm))
        self._e_lat = law.e_lat_kpa * KPA / law.h_mm  # tension side: the bonded lattice, linear
        if membrane_n_per_mm < 0.0:
            raise ValueError(f"membrane_n_per_mm={membrane_n_per_mm!r}: the sheet's tension stiffness must be >= 0")
        # large deflection: the hemisphere's sheet only (a cylindrical bend with free sides has none)
        self.membrane = membrane_n_per_mm if kind == "hemisphere" else 0.0
        self.poisson = poisson
        if wrinkle_n_per_mm is not None and wrinkle_n_per_mm < 0.0:
            raise ValueError(f"wrinkle_n_per_mm={wrinkle_n_per_mm!r}: the compression a sheet carries before it "
                             "wrinkles must be >= 0 (None: it never wrinkles)")
        self.wrinkle = wrinkle_n_per_mm
        if self.membrane > 0.0:
            self._seg_rm = rm = (np.arange(len(self.x) - 1) + 0.5) * step_mm  # between neighbouring grid points
            on = rm + 0.5 * step_mm <= pad_radius_mm + 1e-9  # the sheet ends at the pad's edge
            self._seg_area = np.where(on, 2.0 * np.pi * rm * step_mm, 0.0)  # ring areas
            self._seg_q = 0.5 / rm  # d(u / r) / du at either end (u at the midpoint, their mean)
            self._u_free = np.zeros(len(self.x), bool)  # u(0) = 0 by symmetry; nothing beyond the sheet's edge
            self._u_free[1:int(np.flatnonzero(on).max()) + 2] = True

    def _operators(self, rigidity: np.ndarray) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """lap (D lap w) - G_p lap w for a rigidity field D (axisymmetric and first angular mode).
        D = 0 off the pad: bending moment and shear vanish at the edge; a vanishing stiffness
        there keeps the cut-off margin determined (it carries no load)."""
        d = sp.diags(np.where(self.on_pad, rigidity, 1e-9 * self.rigidity))
        gp = sp.diags(self._gp)
        lin = (self._lap @ d @ self._lap - gp @ self._lap).tocsc() + sp.eye(len(self.x), format="csc") * 1e-9
        lin1 = (self._lap1 @ d @ self._lap1 - gp @ self._lap1).tocsc() if self.kind == "hemisphere" else lin
        return lin, lin1

    def composite_degree(self, w_mm: np.ndarray, contact: np.ndarray, found: np.ndarray,
                         rigidity: np.ndarray) -> np.ndarray:
        """eta(x) of `FrictionInterface` at a solved state (pressures in N/mm^2)."""
        itf = self.interface
        net = contact - found  # load the sheet hands on (down positive)
        if self.kind == "hemisphere":
            inside = np.cumsum(net * self.area) / (2.0 * np.pi)  # int_0^r net r dr
            with np.errstate(invalid="ignore", divide="ignore"):
                total = np.where(self.x > 0, inside / np.maximum(self.x, 1e-12), 0.0)
        else:
            # from the axis outwards (trapezoids: odd across it for an even load, as it must be;
            # a one-sided sum counted the axis's cell on one side only and tilted the solution)
            mid = len(self.x) // 2
            c = np.concatenate([[0.0], np.cumsum(0.5 * (net[1:] + net[:-1]))]) * self.step
            total = c - c[mid]
        # the lattice walls (Pasternak) carry G_p |w'| of it; the sheet carries the rest
        shear = np.abs(total) - self._gp * np.abs(np.gradient(w_mm, self.step))
        shear = np.maximum(shear, 0.0)
        sandwich_share = (itf.sandwich_n_mm - itf.own_n_mm) / np.maximum(rigidity, 1e-12)
        demand = shear * np.clip(sandwich_share, 0.0, 1.0) / itf.separation_mm
        clamp = np.maximum(0.5 * (contact + found), 0.0)  # mean pressure through the sheet
        capacity = itf.friction * clamp
        eta = np.where(demand > capacity, capacity / np.maximum(demand, 1e-15), 1.0)
        return np.where(self.on_pad, eta, 0.0)

    def indenter_height(self, x_mm: np.ndarray) -> np.ndarray:
        """Height of the indenter's surface above its lowest point (inf beyond its radius)."""
        x = np.abs(x_mm)
        z = np.full(x.shape, np.inf)
        inside = x < self.radius
        z[inside] = self.radius - np.sqrt(self.radius**2 - x[inside] ** 2)
        return z

    def foundation(self, w_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lattice pressure (N/mm^2) and its slope (N/mm^3) at compression w (tension linear)."""
        w = np.asarray(w_mm, float)
        eps = 1e-6
        comp = np.maximum(w, 0.0)
        p = np.where(w >= 0.0, self.law.pressure_kpa(comp) * KPA, self._e_lat * w)
        slope = np.where(w >= 0.0, (self.law.pressure_kpa(comp + eps) - self.law.pressure_kpa(np.maximum(comp - eps, 0.0)))
                         * KPA / (comp + eps - np.maximum(comp - eps, 0.0)), self._e_lat)
        if self.rim_mm > 0:  # the solid rim: linear, in compression and tension (it is bonded)
            p = np.where(self.rim, self._k_rim * w, p)
            slope = np.where(self.rim, self._k_rim, slope)
        p = np.where(self.on_pad, p, 0.0)
        slope = np.where(self.on_pad, slope, 0.0)
        return p, slope

    def solve(self, delta_mm: float, w_start: np.ndarray | None = None, tol: float = 1e-9,
              max_iter: int = 60, eta_start: np.ndarray | None = None,
              u_start: np.ndarray | None = None) -> LaminateSolution:
        """Equilibrium at indentation delta (w_start, u_start: a nearby state's deflection and
        radial displacement). With a `FrictionInterface` the rigidity field follows the state:
        solve, update eta from the solved pressures (under-relaxed), solve again until eta
        settles."""
        if self.interface is None:
            rig = np.full(len(self.x), self.rigidity)
            return self._solve_fixed(delta_mm, self._linear, rig, w_start, tol, max_iter, u_start)
        itf = self.interface
        eta = np.ones(len(self.x)) if eta_start is None else eta_start.copy()
        sol = None
        for _ in range(40):
            rig = itf.own_n_mm + eta * (itf.sandwich_n_mm - itf.own_n_mm)
            lin, _ = self._operators(rig)
            sol = self._solve_fixed(delta_mm, lin, rig, w_start if sol is None else sol.w_mm, tol, max_iter,
                                    u_start if sol is None else sol.u_mm)
            new = self.composite_degree(sol.w_mm, sol.contact_kpa * KPA, sol.foundation_kpa * KPA, rig)
            change = float(np.max(np.abs(new - eta)))
            eta = 0.5 * eta + 0.5 * new
            if change < 2e-3:
                break
        sol.composite = eta
        sol.rigidity_n_mm = itf.own_n_mm + eta * (itf.sandwich_n_mm - itf.own_n_mm)
        return sol

    def _solve_fixed(self, delta_mm: float, a, rigidity: np.ndarray, w_start: np.ndarray | None, tol: float,
                     max_iter: int, u_start: np.ndarray | None = None) -> LaminateSolution:
        """Newton with backtracking on the residual, for a fixed rigidity field. In large
        deflection the unknowns are w and the radial u together; u's rows are its in-plane
        equilibrium, per node area as w's are."""
        n = len(self.x)
        big = self.membrane > 0.0
        w = np.zeros(n) if w_start is None else w_start.copy()
        u = np.zeros(n) if (u_start is None or not big) else u_start.copy()
        kc = self.k_cover

        def residual(w, u):
            gap = delta_mm - self.z_ind - w
            pf, slope = self.foundation(w)
            res = a @ w + pf - kc * np.maximum(gap, 0.0)
            if not big:
                return res, slope, gap, None
            f, k_m, _ = self.membrane_forces(w, u)
            res = np.concatenate([res + f[:n] / self.area, np.where(self._u_free, f[n:] / self.area, u)])
            return res, slope, gap, k_m

        res, slope, gap, k_m = residual(w, u)
        norm = np.linalg.norm(res)
        it = 0
        scale = max(kc * max(delta_mm, 1e-3), 1e-12)
        while it < max_iter and norm > tol * scale:
            it += 1
            jac = a + sp.diags(slope + kc * (gap > 0.0))
            if big:
                keep = np.concatenate([np.ones(n), self._u_free])
                per_area = sp.diags(keep / np.concatenate([self.area, self.area]))
                jac = sp.block_diag([jac, sp.diags(1.0 - self._u_free)]) + per_area @ k_m
            step = spla.spsolve(jac.tocsc(), -res)
            dw, du = step[:n], (step[n:] if big else 0.0)
            s = 1.0
            while True:
                w_new, u_new = w + s * dw, u + s * du
                r_new, sl_new, gap_new, k_new = residual(w_new, u_new)
                n_new = np.linalg.norm(r_new)
                if n_new < (1.0 - 1e-4 * s) * norm or s < 1e-4:
                    break
                s *= 0.5
            w, u, res, slope, gap, k_m, norm = w_new, u_new, r_new, sl_new, gap_new, k_new, n_new
        pf, _ = self.foundation(w)
        pc = kc * np.maximum(delta_mm - self.z_ind - w, 0.0)
        forces = self.membrane_forces(w, u)[2] if big else None
        return LaminateSolution(delta_mm, w, pc / KPA, pf / KPA, it, rigidity, None, u if big else None, forces)

    def membrane_forces(self, w_mm: np.ndarray, u_mm: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix, tuple]:
        """The sheet's membrane in large deflection (hemisphere): its strain energy's gradient
        (N, on [w, u]), its Hessian, and (N_r, N_theta) between neighbouring grid points.

        Between grid points j and j + 1 (ring area A, mid radius r_m): e_r = u' + w'^2 / 2,
        e_theta = u / r_m (u the two's mean), U = A C / 2 (e_r^2 + 2 nu e_r e_theta + e_theta^2)."""
        n, h, c, nu = len(self.x), self.step, self.membrane, self.poisson
        b = np.diff(w_mm) / h
        q = self._seg_q
        e_r = np.diff(u_mm) / h + 0.5 * b * b
        e_t = (u_mm[:-1] + u_mm[1:]) * q
        area = self._seg_area
        on = area > 0.0  # beyond the sheet's edge nothing stretches
        n_r, n_t = np.where(on, c * (e_r + nu * e_t), 0.0), np.where(on, c * (e_t + nu * e_r), 0.0)
        one = np.full(len(b), 1.0 / h)
        zero = np.zeros(len(b))
        g_r = np.stack([-one, one, -b / h, b / h], axis=1)  # d e_r / d [u_j, u_j+1, w_j, w_j+1]
        g_t = np.stack([q, q, zero, zero], axis=1)
        # the membrane's tangent stiffness d[N_r, N_t] / d[e_r, e_t]: plane stress, unless it wrinkles
        t_rr, t_rt, t_tt = np.full(len(b), c), np.full(len(b), c * nu), np.full(len(b), c)
        if self.wrinkle is not None:
            n_r, n_t, t_rr, t_rt, t_tt = _tension_field(e_r, e_t, c, nu, self.wrinkle, on)
        f_loc = area[:, None] * (n_r[:, None] * g_r + n_t[:, None] * g_t)
        k_loc = area[:, None, None] * (t_rr[:, None, None] * np.einsum("si,sj->sij", g_r, g_r)
                                       + t_tt[:, None, None] * np.einsum("si,sj->sij", g_t, g_t)
                                       + t_rt[:, None, None] * (np.einsum("si,sj->sij", g_r, g_t)
                                                                + np.einsum("si,sj->sij", g_t, g_r)))
        geo = area * n_r / (h * h)  # N_r d2 e_r / dw2: the membrane force's pull on the sheet's slope
        k_loc[:, 2, 2] += geo
        k_loc[:, 3, 3] += geo
        k_loc[:, 2, 3] -= geo
        k_loc[:, 3, 2] -= geo
        seg = np.arange(len(b))
        idx = np.stack([n + seg, n + seg + 1, seg, seg + 1], axis=1)  # [w (n), u (n)]
        f = np.zeros(2 * n)
        np.add.at(f, idx, f_loc)
        k = sp.csr_matrix((k_loc.ravel(), (np.repeat(idx, 4, axis=1).ravel(), np.tile(idx, (1, 4)).ravel())),
                          shape=(2 * n, 2 * n))
        return f, k, (n_r, n_t)

    def _operator_m1(self, sol: LaminateSolution | None) -> sp.csr_matrix:
        """The first angular mode's plate operator at a solved state (None: the unloaded sheet):
        its rigidity field and, in large deflection, the state's membrane forces acting on the
        mode's slope, -[(1/r)(r N_r w1')' - N_theta w1 / r^2] (zero for a rigid tilt w1 = r, by
        the membrane's in-plane equilibrium). The mode's own stretching (N from w0' w1') is left
        out: a first-order couple tilts the dish more than it stretches it."""
        if sol is None:
            return self._linear1
        lin1 = self._linear1 if self.interface is None else self._operators(sol.rigidity_n_mm)[1]
        if sol.membrane_n_per_mm is None:
            return lin1
        n_r, n_t = sol.membrane_n_per_mm
        n, h = len(self.x), self.step
        r, rm = self.x, self._seg_rm
        n_t_node = np.zeros(n)
        n_t_node[1:-1] = 0.5 * (n_t[:-1] + n_t[1:])
        n_t_node[-1] = 0.5 * n_t[-1]
        out = np.zeros(n)  # r_{j+1/2} N_{j+1/2}; the last point has none
        out[1:-1] = rm[1:] * n_r[1:]
        inn = np.zeros(n)
        inn[1:] = rm * n_r
        main = np.zeros(n)
        main[1:] = (out[1:] + inn[1:]) / (r[1:] * h * h) + n_t_node[1:] / r[1:] ** 2
        up = np.zeros(n - 1)
        up[1:] = -out[1:-1] / (r[1:-1] * h * h)  # row j, column j + 1 (row 0 is the mode's w1(0) = 0)
        lo = np.zeros(n - 1)
        lo[1:] = -inn[2:] / (r[2:] * h * h)  # row j, column j - 1; the coupling to w1(0) = 0 dropped
        return (lin1 + sp.diags([lo, main, up], [-1, 0, 1])).tocsr()

    def couple(self, sol: LaminateSolution, lattice_share: float) -> CoupleResponse:
        """Response to a unit couple of the shear about the deep plane, the cover's route only
        (see CoupleResponse; the lattice's route is `edge_couple`).

        The traction takes two levers down to the deep plane. The cover carries it from the cap
        to the sheet under the contact (tau_c = F_t p_c / F_z, lever t_c + the sheet: a moment
        density local to the contact). The sheet, stiff in its plane, hands it to the lattice as
        a uniform traction over the pad (tau_L = F_t / A_pad, as the lattice's stiffness G A / h
        assumes), whose moment ends at the pad's edge, wherever the contact is (`edge_couple`).
        `lattice_share` s is the lattice's lever over H: this response carries 1 - s.

        A couple density m along the shear loads the sheet like a pressure dm/dx: the cover's
        (1 - s) p_c / F_z under the contact, times cos(phi) (hemisphere) or across the rod (per
        unit length), for F_t H = 1. The sheet's bending hands it to the lattice and, where the
        cover touches the cap, partly to the cap (the stage holds it)."""
        if not 0.0 <= lattice_share <= 1.0:
            raise ValueError(f"lattice_share={lattice_share!r}: the lattice's part of the lever, in [0, 1]")
        pc = sol.contact_kpa * KPA
        fz = float(pc @ self.area)
        n = len(self.x)
        if fz <= 0.0:
            zero = np.zeros(n)
            return CoupleResponse(zero, zero.copy(), zero.copy())
        _, slope = self.foundation(sol.w_mm)
        touching = pc > 0.0
        # the cover's part: -d/dx of (1 - s) p_c / F_z (sign: the deep pressure moves along the shear)
        load = -np.gradient((1.0 - lattice_share) * pc / fz, self.step)
        w1 = self._solve_m1(self._operator_m1(sol) + sp.diags(slope + self.k_cover * touching), load)
        return CoupleResponse(w1, -self.k_cover * touching * w1 / KPA, self._lattice_m1(w1, slope) / KPA)

    def edge_couple(self, sol: LaminateSolution | None = None) -> CoupleResponse:
        """Response to a unit couple handed to the lattice over the whole pad: the lattice's route
        of the shear's moment (lever s H of `couple`) and of the columns' lean (F_z u).

        The lattice is a thin layer in shear. Across its height h the shear stress is uniform, so
        vertical equilibrium makes its normal stress change by h dtau/dx from its top to its base:
        nothing inside the pad, where tau is uniform, and a band at the pad's edge, where tau
        falls to zero as the bonded layer's end effect (the side is free; it dies away over
        `edge_fade_mm(h)`, about a quarter of h), in the pad's solid rim where it has one, which
        carries more of it (`side_load`). Its compression follows the mean
        of the two, so with the top at p_top = k w - h tau'/2 and the base at p_base = k w + h
        tau'/2 the edge term splits in halves: one loads the sheet (D lap^2 w + k w = h tau'/2),
        whose bending spreads it, the other the lattice hands straight to the deep sheet
        (`CoupleResponse.direct_kpa`). Together they carry the whole couple; the deep sheet reads
        the base (foundation_kpa), the sheet the top (foundation_kpa - 2 direct_kpa).

        The edge lies on the pad, not about the contact, so the fast model takes this from the
        "rod" geometry (a straight edge, per unit length along it) on the unloaded lattice
        (sol None: its tangent stiffness at zero compression, the sheet's own rigidity, as where
        no lattice pressure clamps the films) and adds it at the pad's four sides. With a loaded
        sol, the state's tangent stiffness and rigidity (how `couple` carried it before the
        routes were split: their sum is that response)."""
        n = len(self.x)
        w = np.zeros(n) if sol is None else sol.w_mm
        touching = np.zeros(n, bool) if sol is None else sol.contact_kpa > 0.0
        lin1 = self._operator_m1(sol)
        _, slope = self.foundation(w)
        edge_term = self.side_load()
        w1 = self._solve_m1(lin1 + sp.diags(slope + self.k_cover * touching), 0.5 * edge_term)
        direct = 0.5 * edge_term / KPA
        return CoupleResponse(w1, -self.k_cover * touching * w1 / KPA, self._lattice_m1(w1, slope) / KPA + direct,
                              direct)

    def side_load(self) -> np.ndarray:
        """The lattice's shear traction's term h tau' at the pad's sides (odd across the pad),
        normalised to a unit moment.

        The in-plane-stiff sheet shears the whole pad by one strain, so the traction is each
        material's shear modulus times it, and it fades to zero inside the free side as the
        bonded layer's end effect, tau ~ 1 - exp(-s / l), s in from the side, l =
        edge_fade_mm(h). Without a rim that is the lattice's, and h tau' lies on the pad as
        exp(-s / l) / l. With a rim of width b the fade is the rim's own, r (1 - exp(-s / l))
        with r = 2 / rho its shear modulus over the lattice's, and where the rim meets the
        lattice (s = b) the traction steps from the lattice's 1 to r (1 - exp(-b / l)), a line
        load of the other sign: h tau' = r exp(-s / l) / l in the rim less that step at s = b.
        Both put one lattice traction's worth of net side load on each side."""
        fade = edge_fade_mm(self.law.h_mm)
        inside = np.clip(self.pad_radius - np.abs(self.x), 0.0, None)
        if self.rim_mm > 0:
            cfg = self.law.cfg
            r = cfg.solid_shear_modulus_kpa / cfg.shear_modulus_kpa
            b = self.rim_mm
            density = np.where(self.rim, r * np.exp(-inside / fade) / fade, 0.0)
            # the step, on each side's first grid point inside the rim's face
            for sign in (-1.0, 1.0):  # (the hemisphere's radius has one side)
                lattice = np.flatnonzero(self.on_pad & ~self.rim & (sign * self.x > 0))
                if len(lattice) == 0:
                    continue
                face = lattice[np.argmin(inside[lattice])]
                density[face] -= (r * (1.0 - math.exp(-b / fade)) - 1.0) / self.step
        else:
            density = np.exp(-inside / fade) / fade
        edge = np.where(self.on_pad, np.sign(self.x) * density, 0.0)
        return edge / self.first_moment(edge / KPA)  # (first_moment reads kPa)

    def side_inset_mm(self) -> float:
        """How far inside the pad's side the side load's moment acts (its centroid: the lever of
        a pair of sides is 2 (L - inset)); h / 4.21 without a rim, negative where the rim's
        couple outweighs its net load."""
        edge, half = self.side_load(), self.x > 0
        net = float(edge[half].sum())
        return float(self.pad_radius - (edge[half] * self.x[half]).sum() / net)

    def _solve_m1(self, jac, load: np.ndarray) -> np.ndarray:
        """Deflection of the first angular mode (hemisphere; the rod's odd one) under load."""
        load = load.copy()
        if self.kind == "hemisphere":
            load[0] = 0.0
            jac = jac.tolil()
            jac[0, :] = 0.0
            jac[0, 0] = 1.0
        w1 = spla.spsolve(jac.tocsc(), load)
        if self.kind == "hemisphere":
            w1[0] = 0.0
        return w1

    def flank(self, sol: LaminateSolution) -> tuple[CoupleResponse, float]:
        """Response to the cap moving tangentially by a unit distance v relative to the sheet
        under it, and the cover's stiffness against that motion (N/mm; rod: per mm of length).

        The cover is a thin soft layer between the rigid cap and the sheet. Moving the cap by v
        along x (the sheet held) shears the cover over the contact (traction G_c v / t_c) and,
        because the cap is curved and sunk into the stack, squeezes the cover more on the
        leading flank and less on the trailing one: the cover's compression changes by
        v dz_ind/dx, its pressure by k_c v dz_ind/dx (first angular mode). That flank pressure
        loads the sheet like a couple; the sheet deflects under it (w1) and gives most of the
        squeeze back. Returns the response per unit v (contact and lattice pressure changes,
        including the flank pressure itself) and the stiffness, the traction's alone.

        Where the pad is uniform the response is the solved state moved with the cap (w1 =
        -dw/dx: a shape moved across a uniform foundation keeps its energy), and the flank's
        pressure on the cap's slope is given back by the tilt of the cap's normal, which moved
        with it (`flank_force`; within a few per cent of the traction where the sheet's bending is
        uniform, tests/sim/test_cover_shear.py). Counting the flank pressure alone, without the
        sheet's response and the slope's change, made the cover several times too stiff in shear
        under a deep press (3.4x the 3D half-model's tangential stiffness at 3 N, `yardstick3d`)."""
        pc = sol.contact_kpa * KPA
        n = len(self.x)
        touching = pc > 0.0
        if not touching.any():
            zero = np.zeros(n)
            return CoupleResponse(zero, zero.copy(), zero.copy()), 0.0
        _, slope = self.foundation(sol.w_mm)
        kc = self.k_cover
        dp = kc * self._cap_slope()[0] * touching  # N/mm^2 per mm of v
        w1 = self._solve_m1(self._operator_m1(sol) + sp.diags(slope + kc * touching), dp)
        dpc = dp - kc * touching * w1
        return CoupleResponse(w1, dpc / KPA, self._lattice_m1(w1, slope) / KPA), self.traction_stiffness(sol)

    def traction_stiffness(self, sol: LaminateSolution) -> float:
        """The cover's tangential stiffness under the cap (`flank`): G_c / t_c over the contact."""
        return self.cover_shear_n_per_mm3 * float((sol.contact_kpa > 0.0) @ self.area)

    def _cap_slope(self) -> tuple[np.ndarray, np.ndarray]:
        """The cap's slope dz/dx along a motion (the first mode's amplitude: cos(phi) for the
        disc) and the mean over that mode of d2z/dx2 (disc: (z'' + z'/r) / 2; rod: z'')."""
        r = np.abs(self.x)
        s = np.sqrt(np.maximum(self.radius**2 - r * r, 1e-12))
        d2z = self.radius**2 / s**3
        if self.kind == "hemisphere":
            d2z = 0.5 * (d2z + 1.0 / s)
        return self.x / s, d2z

    def flank_force(self, sol: LaminateSolution, response: CoupleResponse) -> float:
        """The change of the contact's tangential force (N per mm of v; rod: per mm of length)
        beyond the traction, from the flank response `flank` returned: the flank pressure left
        on the cap's slope less the cap's whole contact pressure on the change of that slope
        (the cap moved, its normal at a fixed point tilted by v d2z/dx2)."""
        dz, d2z = self._cap_slope()
        half = 0.5 if self.kind == "hemisphere" else 1.0  # the disc's cos(phi)^2 mean
        return half * float((response.contact_kpa * KPA * dz) @ self.area) \
            - float((sol.contact_kpa * KPA * d2z) @ self.area)

    def _lattice_m1(self, w1: np.ndarray, slope: np.ndarray) -> np.ndarray:
        """What the lattice hands the deep sheet (N/mm^2) for a first-mode deflection w1: its
        compression (slope w1) and what its walls carry in shear (-G_p lap w1, the Pasternak
        part of the operator), which is where the pad's edge takes a load near it."""
        return slope * w1 - self._gp * (self._lap1 @ w1)

    def first_moment(self, amplitude_kpa: np.ndarray) -> float:
        """Moment (N mm, about the axis through the contact, per unit couple) of an amplitude:
        pi int p r^2 dr (cos(phi) mode) or int p d dd (rod, per unit length)."""
        a = np.asarray(amplitude_kpa) * KPA
        if self.kind == "hemisphere":
            return float(np.pi * (a * self.x**2).sum() * self.step)
        return float((a * self.x).sum() * self.step)

    def load(self, sol: LaminateSolution) -> float:
        """Normal force (hemisphere, N) or line load (rod, N/mm) on the indenter."""
        return float(sol.contact_kpa @ self.area) * KPA


def _tension_field(e_r: np.ndarray, e_t: np.ndarray, c: float, nu: float, cap: float, on: np.ndarray):
    """A membrane that wrinkles (a relaxed, tension-field membrane): in the direction where plane
    stress would compress it past `cap` (N/mm, the compression it carries before it wrinkles;
    0: none), the force stays at -cap and the strain there is taken up by the wrinkles; the
    other direction then stretches as a strip, E t = c (1 - nu^2). Returns N_r, N_t and the
    tangent d[N_r, N_t] / d[e_r, e_t] (rr, rt, tt). The energy stays continuous and convex, so
    Newton sees a smooth-enough residual. Wrinkles in both directions: both forces at -cap."""
    strip = c * (1.0 - nu * nu)
    n_r, n_t = c * (e_r + nu * e_t), c * (e_t + nu * e_r)
    t_rr, t_rt, t_tt = np.full(len(e_r), c), np.full(len(e_r), c * nu), np.full(len(e_r), c)
    hoop_r = strip * e_r - nu * cap  # N_r with the hoop direction wrinkled
    radial_t = strip * e_t - nu * cap  # N_t with the radial direction wrinkled
    hoop = (n_t < -cap) & (hoop_r >= -cap)
    radial = (n_r < -cap) & (radial_t >= -cap) & ~hoop
    both = ((n_t < -cap) | (n_r < -cap)) & ~hoop & ~radial
    n_r = np.where(hoop, hoop_r, np.where(radial | both, -cap, n_r))
    n_t = np.where(radial, radial_t, np.where(hoop | both, -cap, n_t))
    t_rr = np.where(hoop, strip, np.where(radial | both, 0.0, t_rr))
    t_tt = np.where(radial, strip, np.where(hoop | both, 0.0, t_tt))
    t_rt = np.where(hoop | radial | both, 0.0, t_rt)
    return np.where(on, n_r, 0.0), np.where(on, n_t, 0.0), t_rr, t_rt, t_tt


def sheet_rigidity_n_mm(film_modulus_mpa: float, film_mm: float, copper_modulus_mpa: float, copper_mm: float,
                        electrode_fill: float, core_mm: float, core_modulus_mpa: float, bonded: bool,
                        poisson: float = SHEET_POISSON) -> float:
    """Bending rigidity D (N mm) of one FSR sheet: two electrode films (polyimide + copper strips,
    strips of the two films crossed) around the Velostat core.

    Along its strips a film is stiff in tension (copper over `electrode_fill` of the width),
    across them it stretches through the polyimide gaps (strips and gaps in series). Bonded,
    the films act as the faces of a sandwich about the core: in each direction one face is the
    along-strip film and the other the across-strip one, D = E1 E2 / (E1 + E2) d^2 (E_i A_i per
    width, d the distance between the films' mid-planes), plus each film's own bending. Not
    bonded, only the films' and the core's own bending add up. Crossed strips make x and y
    alike, so the sheet is taken as isotropic."""
    along, across = film_tension_n_per_mm(film_modulus_mpa, film_mm, copper_modulus_mpa, copper_mm, electrode_fill)
    t = film_mm + copper_mm
    # own bending of one film along its strips (two-layer beam about its neutral axis)
    e1, t1, e2, t2 = film_modulus_mpa, film_mm, electrode_fill * copper_modulus_mpa, copper_mm
    zn = (e1 * t1 * t1 / 2 + e2 * t2 * (t1 + t2 / 2)) / (e1 * t1 + e2 * t2)
    own_along = e1 * (t1**3 / 12 + t1 * (t1 / 2 - zn) ** 2) + e2 * (t2**3 / 12 + t2 * (t1 + t2 / 2 - zn) ** 2)
    own_across = film_modulus_mpa * film_mm**3 / 12  # the gaps hinge: polyimide alone
    own = (own_along + own_across) / (1 - poisson**2)  # one along + one across film per direction
    core = core_modulus_mpa * core_mm**3 / (12 * (1 - 0.4**2))
    if not bonded:
        return own + core
    d = core_mm + t
    return along * across / (along + across) * d * d / (1 - poisson**2) + own + core


def film_tension_n_per_mm(film_modulus_mpa: float, film_mm: float, copper_modulus_mpa: float, copper_mm: float,
                          electrode_fill: float) -> tuple[float, float]:
    """An electrode film's tension stiffness per width (N/mm) along its strips (copper over
    `electrode_fill` of the width beside the polyimide) and across them (strips and polyimide gaps
    in series)."""
    pi_a = film_modulus_mpa * film_mm
    cu_a = copper_modulus_mpa * copper_mm
    along = pi_a + electrode_fill * cu_a
    across = 1.0 / (electrode_fill / (pi_a + cu_a) + (1.0 - electrode_fill) / pi_a)
    return along, across


def sheet_membrane_n_per_mm(film_modulus_mpa: float, film_mm: float, copper_modulus_mpa: float, copper_mm: float,
                            electrode_fill: float, core_mm: float, core_modulus_mpa: float,
                            poisson: float = SHEET_POISSON) -> float:
    """Membrane stiffness C = E t / (1 - nu^2) (N/mm) of one FSR sheet stretched in its plane.

    Each film stretches with the sheet whether it sticks to the Velostat or slips on it (slip
    frees the films' relative shear, not their own tension), so in either direction one film's
    along-strip and the other's across-strip stiffness add, with the core's (E t = 2.0 kN/mm,
    C = 2.3 kN/mm with the defaults), taken as isotropic as the sheet's bending is."""
    along, across = film_tension_n_per_mm(film_modulus_mpa, film_mm, copper_modulus_mpa, copper_mm, electrode_fill)
    return (along + across + core_modulus_mpa * core_mm) / (1.0 - poisson**2)


def cover_stiffness_n_per_mm3(modulus_kpa: float, thickness_mm: float, confinement_mm: float) -> float:
    """Compression stiffness per area of the thin bonded cover: an incompressible layer squeezed
    over a half-width L stiffens by 1 + 2 S^2, S = L / 2t (Gent & Lindley)."""
    s = confinement_mm / (2.0 * thickness_mm)
    return modulus_kpa * KPA * (1.0 + 2.0 * s * s) / thickness_mm


def cover_shear_stiffness_n_per_mm3(modulus_kpa: float, poisson: float, thickness_mm: float) -> float:
    """Simple-shear stiffness per area of the thin cover, G / t with G = E / 2 (1 + nu)."""
    return modulus_kpa * KPA / (2.0 * (1.0 + poisson)) / thickness_mm


def pad_radius_mm(kind: str, pad_width_mm: float) -> float:
    """Where the plate ends: the disc of the pad's area (hemisphere) or half the width (rod)."""
    return pad_width_mm / math.sqrt(math.pi) if kind == "hemisphere" else pad_width_mm / 2.0
