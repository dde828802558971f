"""Contact of a rigid indenter (hemisphere or rod) with the thin soft stack.

Hertz does not apply here: the contact radius exceeds the indenter radius long before the
study's loads, and the 2.7 mm stack is far thinner than the contact is wide. Instead each
point of the spacer carries the pressure of its own compression (nonlinear Winkler, see
`spacer.SpacerLaw`) under the rigid profile; the cover and the lattice's shear coupling
(Pasternak length) spread that pressure over the surface, and the spacer spreads it further
on its way to the deep layer. All of it is precomputed once per design as tables over the
indentation depth:

- hemisphere: axisymmetric radial profiles p(delta, r);
- rod: line-contact profiles p(delta, d) across the axis, per unit length along it.

Tables also hold the normal force (or line load), the spacer's tangential and torsional
stiffness under the contact, the friction radius, and the exponential-tilt parameters that
put the deep pressure centre where moment equilibrium demands (`tilt_*`).
Lengths mm, pressures kPa, forces N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import i0e, i1e

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.spacer import SpacerLaw

KPA_MM2_TO_N = 1e-3
MAX_TILT_SHIFT_MM = 6.0  # largest deep-CoP shift the tilt tables cover (friction keeps it < mu*H)
_N_SHIFT = 49


@dataclass
class ContactTables:
    """Precomputed contact response of one indenter on one stack design.

    Row k of every (n_delta, ...) table is indentation delta_mm[k] (uniform grid).
    `load` is the normal force (hemisphere, N) or line load (rod, N/mm).
    Profiles are sampled on the uniform grid `dist_mm` (radius or signed distance to the axis).
    """

    kind: str
    delta_mm: np.ndarray  # (n_delta,)
    load: np.ndarray  # (n_delta,) N or N/mm
    dist_mm: np.ndarray  # (n_dist,)
    superficial_kpa: np.ndarray  # (n_delta, n_dist) after cover/Pasternak smoothing
    deep_kpa: np.ndarray  # (n_delta, n_dist) after spreading through the spacer
    shear_extra: np.ndarray  # (n_delta,) contact's extra tangential stiffness, N/mm (rod: per mm)
    torsion_extra: np.ndarray  # (n_delta,) hemisphere: extra torsional stiffness N mm/rad
    friction_radius_mm: np.ndarray  # (n_delta,) int p r dA / int p dA (hemisphere)
    contact_halfwidth_mm: np.ndarray  # (n_delta,) contact radius / half-width of the Winkler zone
    tilt_shift_mm: np.ndarray  # (n_shift,) uniform grid of deep-CoP shifts
    tilt_gamma: np.ndarray  # (n_delta, n_shift) exponential-tilt rate 1/mm giving that shift
    tilt_logz: np.ndarray  # (n_delta, n_shift) log normaliser of the tilt

    @property
    def d_delta(self) -> float:
        return float(self.delta_mm[1] - self.delta_mm[0])

    @property
    def d_dist(self) -> float:
        return float(self.dist_mm[1] - self.dist_mm[0])


def _profile_height(kind: str, radius_mm: float, d: np.ndarray) -> np.ndarray:
    """Height of the indenter surface above its lowest point at distance d (inf outside)."""
    d = np.abs(d)
    inside = d < radius_mm
    h = np.full(d.shape, np.inf)
    h[inside] = radius_mm - np.sqrt(radius_mm**2 - d[inside] ** 2)
    return h


def _radial_gauss_matrix(r_out: np.ndarray, r_in: np.ndarray, dr_in: float, sigma: float) -> np.ndarray:
    """Matrix M with (f * G_sigma)(r_out) = M @ f(r_in) for axisymmetric f (2D Gaussian blur)."""
    s2 = sigma * sigma
    ro, ri = r_out[:, None], r_in[None, :]
    # exp(-(r^2 + r'^2)/2s^2) I0(r r'/s^2) written with the scaled Bessel for stability
    return (ri / s2) * np.exp(-((ro - ri) ** 2) / (2 * s2)) * i0e(ro * ri / s2) * dr_in


def _line_gauss_matrix(d_out: np.ndarray, d_in: np.ndarray, dd_in: float, sigma: float) -> np.ndarray:
    return np.exp(-((d_out[:, None] - d_in[None, :]) ** 2) / (2 * sigma**2)) / (math.sqrt(2 * math.pi) * sigma) * dd_in


def _tilt_tables(kind: str, dist: np.ndarray, deep: np.ndarray, dd: float):
    """For each row: the tilt rate gamma and log-normaliser that shift the centre by s.

    Tilted map p(x) exp(gamma xi) / Z with xi the coordinate along the shear. For a radial
    profile the angular integrals are 2 pi I0(gamma r) and 2 pi r I1(gamma r) (scaled Bessels
    keep the exponentials in range); for a line profile it is a 1D integral.
    """
    shifts = np.linspace(0.0, MAX_TILT_SHIFT_MM, _N_SHIFT)
    n = deep.shape[0]
    gam = np.zeros((n, _N_SHIFT))
    logz = np.zeros((n, _N_SHIFT))
    for k in range(n):
        p = deep[k]
        tot = p.sum()
        if tot <= 0:
            continue
        if kind == "hemisphere":
            var = (p * dist**3).sum() / (p * dist).sum() / 2.0
        else:
            var = (p * dist**2).sum() / tot
        g_hi = 3.0 * MAX_TILT_SHIFT_MM / max(var, 1e-6)
        g = np.linspace(0.0, g_hi, 400)
        gr = g[:, None] * dist[None, :]
        if kind == "hemisphere":
            w = p * dist
            # scaled Bessels: I(x) = Ie(x) e^x; factor e^{gamma r} shared by both integrals
            log_w0 = np.log(np.maximum(w * i0e(gr), 1e-300)) + gr
            log_w1 = np.log(np.maximum(w * dist * i1e(gr), 1e-300)) + gr
            m0 = np.logaddexp.reduce(log_w0, axis=1)
            m1 = np.logaddexp.reduce(log_w1, axis=1)
            s_of_g = np.exp(m1 - m0)
            lz = m0 - math.log(w.sum())
        else:
            log_w = np.log(np.maximum(p, 1e-300))[None, :] + gr
            m0 = np.logaddexp.reduce(log_w, axis=1)
            s_of_g = (np.exp(log_w - m0[:, None]) * dist[None, :]).sum(axis=1)
            lz = m0 - math.log(tot)
        s_of_g = np.maximum.accumulate(s_of_g)
        gam[k] = np.interp(shifts, s_of_g, g)
        logz[k] = np.interp(shifts, s_of_g, lz)
    return shifts, gam, logz


def build_tables(sim: SimConfig, kind: str) -> ContactTables:
    """Integrate the contact model for one indenter over a grid of indentation depths."""
    if kind not in ("hemisphere", "rod"):
        raise ValueError(f"indenter={kind!r}: must be 'hemisphere' or 'rod'")
    law = SpacerLaw(sim.spacer)
    radius = sim.contact.hemisphere_radius_mm if kind == "hemisphere" else sim.contact.rod_diameter_mm / 2
    h = sim.spacer.thickness
    delta_max = min(0.99 * radius, 0.97 * h)
    n_delta = sim.contact.table_points
    delta = np.linspace(0.0, delta_max, n_delta)

    sigma_s = math.hypot(law.pasternak_length_mm(), sim.cover.thickness)
    sigma_d = np.array([math.hypot(sigma_s, float(law.spread_sigma_mm(dl))) for dl in delta])
    a_max = math.sqrt(max(2 * radius * delta_max - delta_max**2, 0.0))
    reach = a_max + 5.0 * float(sigma_d.max())

    fine_step = min(0.01, a_max / 200)
    if kind == "hemisphere":
        r_in = np.arange(0.0, a_max + fine_step, fine_step)
        dist = np.linspace(0.0, reach, 241)
    else:
        r_in = np.arange(-a_max - fine_step, a_max + 2 * fine_step, fine_step)
        dist = np.linspace(-reach, reach, 321)
    ind_h = _profile_height(kind, radius, r_in)
    raw = law.pressure_kpa(np.maximum(delta[:, None] - ind_h[None, :], 0.0))  # (n_delta, n_in)

    if kind == "hemisphere":
        weight = 2 * np.pi * r_in * fine_step  # area of each ring
        blur_s = _radial_gauss_matrix(dist, r_in, fine_step, sigma_s)
    else:
        weight = np.full(r_in.shape, fine_step)  # length per unit rod length
        blur_s = _line_gauss_matrix(dist, r_in, fine_step, sigma_s)
    load = raw @ weight * KPA_MM2_TO_N
    superficial = raw @ blur_s.T
    deep = np.empty_like(superficial)
    for k in range(n_delta):
        blur = (_radial_gauss_matrix if kind == "hemisphere" else _line_gauss_matrix)(
            dist, r_in, fine_step, float(sigma_d[k]))
        deep[k] = blur @ raw[k]

    comp = np.maximum(delta[:, None] - ind_h[None, :], 0.0)
    k_extra = law.shear_stiffness_kpa_per_mm(comp) - law.shear_stiffness_kpa_per_mm(0.0)
    k_extra = np.where(comp > 0, k_extra, 0.0)
    shear_extra = k_extra @ weight * KPA_MM2_TO_N
    torsion_extra = (k_extra * r_in[None, :] ** 2) @ weight * KPA_MM2_TO_N if kind == "hemisphere" else np.zeros(n_delta)
    with np.errstate(invalid="ignore", divide="ignore"):
        fr = (raw * np.abs(r_in)[None, :]) @ weight / (raw @ weight)
    fr = np.nan_to_num(fr)
    halfwidth = np.sqrt(np.maximum(2 * radius * delta - delta**2, 0.0))
    shifts, gam, logz = _tilt_tables(kind, dist, deep, float(dist[1] - dist[0]))
    return ContactTables(kind, delta, load, dist, superficial, deep, shear_extra, torsion_extra, fr,
                         halfwidth, shifts, gam, logz)
