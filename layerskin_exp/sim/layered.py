"""Linear elastic response of the skin's layered stack to surface tractions, layer by layer
(the transfer-matrix solution of a laminate bonded to a rigid base).

What this is for: each FSR reads the normal stress across its Velostat core's mid-plane. How a
contact's pressure and shear traction on the cover reach that plane, spread and tilted by the
stack above it, is an influence function of the stack alone (its layers' thicknesses and
stiffnesses). Here it is computed exactly for the linearised stack: each layer a homogeneous
orthotropic solid (isotropic layers are a special case; the homogenised lattice is stiff through
its thickness and soft in plane), layers bonded, the base rigid, the stack unbounded in plane.

For a surface traction varying as cos(xi x) (pressure) or sin(xi x) (shear along x), each layer's
in-plane (P-SV) field obeys d/dz [Ux, Uz, T, S] = A(xi) [Ux, Uz, T, S], with the displacements
ux = Ux sin(xi x), uz = Uz cos(xi x) and the stresses s_xz = T sin(xi x), s_zz = S cos(xi x)
(z down, from the cover's surface). The same four constants C11, C13, C33, C55 govern the
axisymmetric field of a transversely isotropic stack under a Hankel transform, so one transfer
function serves a line load (plane strain) and a point load (radial wavenumber).

Solved stably for any xi h: the rigid base's zero displacement is carried up as the admittance
u = Y s (a Riccati sweep over sub-layers no thicker than 0.5 / xi), and the surface traction is
then carried down through the same sub-layers, where only decaying parts remain.

Checks (tests/sim/test_layered.py): a deep layer gives the half-space's closed forms, the
pressure's transfer is 1 at xi = 0 at every depth (the plane carries the load) and the shear's
first moment at depth z is the shear times z (the moment balance of the stack above the plane).

Lengths mm, moduli MPa (N/mm^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm


@dataclass(frozen=True)
class Layer:
    """One bonded layer: thickness and its plane-strain (P-SV) stiffness constants."""

    name: str
    thickness_mm: float
    c11: float  # in-plane normal stiffness C_xxxx
    c13: float  # coupling C_xxzz
    c33: float  # through-thickness C_zzzz
    c55: float  # transverse shear C_xzxz

    @classmethod
    def isotropic(cls, name: str, thickness_mm: float, e_mpa: float, nu: float) -> Layer:
        lam = e_mpa * nu / ((1 + nu) * (1 - 2 * nu))
        mu = e_mpa / (2 * (1 + nu))
        return cls(name, thickness_mm, lam + 2 * mu, lam, lam + 2 * mu, mu)

    def matrix(self, xi: np.ndarray) -> np.ndarray:
        """A(xi), shape (len(xi), 4, 4), for the state [Ux, Uz, T, S]."""
        xi = np.asarray(xi, float)
        a = np.zeros(xi.shape + (4, 4))
        r = self.c13 / self.c33
        a[..., 0, 1] = xi
        a[..., 0, 2] = 1.0 / self.c55
        a[..., 1, 0] = -xi * r
        a[..., 1, 3] = 1.0 / self.c33
        a[..., 2, 0] = xi * xi * (self.c11 - self.c13 * r)
        a[..., 2, 3] = xi * r
        a[..., 3, 2] = -xi
        return a


@dataclass(frozen=True)
class Stack:
    """Layers from the cover's surface (first) down to the rigid base (below the last)."""

    layers: tuple[Layer, ...]

    @property
    def thickness_mm(self) -> float:
        return sum(la.thickness_mm for la in self.layers)

    def depth_of(self, name: str, fraction: float = 0.5) -> float:
        """Depth of the plane at `fraction` of layer `name`'s thickness (0.5: its mid-plane)."""
        z = 0.0
        for la in self.layers:
            if la.name == name:
                return z + fraction * la.thickness_mm
            z += la.thickness_mm
        raise KeyError(f"no layer {name!r} in the stack ({', '.join(la.name for la in self.layers)})")

    def transfer(self, xi: np.ndarray, depths_mm, max_step: float = 0.5) -> dict[str, np.ndarray]:
        """Normal-stress transfer functions at the given depths, shape (len(depths), len(xi)):

        - "normal": the compressive normal stress -s_zz per unit surface pressure (cos(xi x));
        - "shear": the compressive normal stress per unit surface shear traction along +x
          (sin(xi x) in, cos(xi x) out).

        xi > 0 (rad/mm). At xi -> 0 the first tends to 1 and the second to 0."""
        xi = np.atleast_1d(np.asarray(xi, float))
        if np.any(xi <= 0):
            raise ValueError("transfer: wavenumbers must be > 0 (the xi -> 0 limits are 1 and 0)")
        depths = np.atleast_1d(np.asarray(depths_mm, float))
        if np.any((depths < 0) | (depths > self.thickness_mm)):
            raise ValueError(f"depths {depths} outside the stack's 0..{self.thickness_mm:.3f} mm")
        # wavenumbers in octaves, each solved on sub-layers sized for its own largest xi
        band = np.floor(np.log2(xi / xi.min())).astype(int)
        if band.max() > 0:
            out = {k: np.zeros((len(depths), len(xi))) for k in ("normal", "shear")}
            for b in np.unique(band):
                m = band == b
                part = self._transfer(xi[m], depths, max_step)
                for k in out:
                    out[k][:, m] = part[k]
            return out
        return self._transfer(xi, depths, max_step)

    def _transfer(self, xi: np.ndarray, depths: np.ndarray, max_step: float) -> dict[str, np.ndarray]:
        # sub-layer boundaries: every layer split so that xi_max * h <= max_step, and every
        # requested depth a boundary
        cuts = [0.0]
        owner = []
        step = max_step / xi.max()
        z = 0.0
        for k, la in enumerate(self.layers):
            inner = [d for d in depths if z < d < z + la.thickness_mm]
            marks = sorted({z, z + la.thickness_mm, *inner})
            for lo, hi in zip(marks[:-1], marks[1:], strict=True):
                n = max(1, int(np.ceil((hi - lo) / step)))
                for j in range(1, n + 1):
                    cuts.append(lo + (hi - lo) * j / n)
                    owner.append(k)
            z += la.thickness_mm
        cuts = np.array(cuts)
        props = []  # per sub-layer, the propagator P (len(xi), 4, 4) from its top to its bottom
        cache: dict[tuple[int, float], np.ndarray] = {}
        for i, k in enumerate(owner):
            h = round(cuts[i + 1] - cuts[i], 12)
            key = (k, h)
            if key not in cache:
                cache[key] = expm(self.layers[k].matrix(xi) * h)
            props.append(cache[key])
        # bottom-up: the admittance Y (u = Y s) at each sub-layer top; rigid base: Y = 0
        nx = len(xi)
        y = np.zeros((nx, 2, 2))
        adm = [None] * len(props)
        for i in range(len(props) - 1, -1, -1):
            p = props[i]
            puu, pus, psu, pss = p[:, :2, :2], p[:, :2, 2:], p[:, 2:, :2], p[:, 2:, 2:]
            y = np.linalg.solve(puu - y @ psu, y @ pss - pus)
            adm[i] = y
        out = {}
        for kind, s0 in (("normal", np.array([0.0, -1.0])), ("shear", np.array([-1.0, 0.0]))):
            s = np.broadcast_to(s0, (nx, 2)).copy()
            at = {0.0: s.copy()}
            for i, p in enumerate(props):
                u = np.einsum("nij,nj->ni", adm[i], s)
                s = np.einsum("nij,nj->ni", p[:, 2:, :2], u) + np.einsum("nij,nj->ni", p[:, 2:, 2:], s)
                at[round(cuts[i + 1], 12)] = s.copy()
            rows = []
            for d in depths:
                key = min(at, key=lambda c, d=d: abs(c - d))
                rows.append(-at[key][:, 1])  # compressive s_zz
            out[kind] = np.array(rows)
        return out


def line_load_response(stack: Stack, x_mm: np.ndarray, pressure: np.ndarray, shear: np.ndarray | None,
                       depths_mm, pad_mm: float = 200.0) -> np.ndarray:
    """Compressive normal stress at `depths_mm` (rows) along x of a plane-strain stack under the
    surface pressure and shear traction given on the uniform grid x_mm (same units out as in).
    The grid is padded to pad_mm with zero load so that the periodic transform stands for the
    unbounded stack."""
    x_mm = np.asarray(x_mm, float)
    dx = float(x_mm[1] - x_mm[0])
    n = int(2 ** np.ceil(np.log2(max(len(x_mm), pad_mm / dx))))
    load = np.zeros((2, n))
    load[0, : len(x_mm)] = pressure
    if shear is not None:
        load[1, : len(x_mm)] = shear
    xi = 2 * np.pi * np.fft.rfftfreq(n, dx)
    depths = np.atleast_1d(np.asarray(depths_mm, float))
    # beyond xi z ~ 40 nothing of the surface load reaches depth z (below e^-40): not computed
    keep = (xi > 0) & (xi * max(depths.min(), 1e-9) < 40.0)
    gn, gt = np.zeros((len(depths), len(xi))), np.zeros((len(depths), len(xi)))
    gn[:, 0] = 1.0
    tr = stack.transfer(xi[keep], depths)
    gn[:, keep], gt[:, keep] = tr["normal"], tr["shear"]
    f = np.fft.rfft(load, axis=1)
    # a shear traction sin(xi x) gives a stress gt cos(xi x), so e^{i xi x} in gives i gt e^{i xi x} out
    resp = gn * f[0] + 1j * gt * f[1]
    return np.fft.irfft(resp, n, axis=1)[:, : len(x_mm)]


def section_stack(sim) -> Stack:
    """The reference section's stack (`fem_reference.model.Section`), linearised: the same layers,
    thicknesses and materials, each film isotropic with its modulus along the section, the lattice
    homogenised (matrix G13 = rho G_s / 2 with lambda = 0, plus the planes' separation stiffness k
    through the thickness: C11 = 2 G13, C13 = 0, C33 = 2 G13 + k = rho E_s, C55 = G13)."""
    from layerskin_exp.sim.fem_reference.model import CORE_NU, FILM_NU, Section, lattice_constants

    sec = Section.from_sim(sim)
    c = lattice_constants(sec)
    iso = Layer.isotropic
    return Stack((iso("cover", sec.cover_mm, sec.cover_e_mpa, sec.cover_poisson()),
                  iso("film_along", sec.film_mm, sec.film_along_e_mpa, FILM_NU),
                  iso("core", sec.core_mm, sec.core_e_mpa, CORE_NU),
                  iso("film_across", sec.film_mm, sec.film_across_e_mpa, FILM_NU),
                  Layer("lattice", sec.lattice_mm, 2 * c["mu"], 0.0, 2 * c["mu"] + c["k"], c["mu"]),
                  iso("deep_film_across", sec.film_mm, sec.film_across_e_mpa, FILM_NU),
                  iso("deep_core", sec.core_mm, sec.core_e_mpa, CORE_NU),
                  iso("deep_film_along", sec.film_mm, sec.film_along_e_mpa, FILM_NU)))


def compare_with_section(state: int = 0, dx: float = 0.01) -> dict:
    """The linearised section under the reference section's own contact pressure (its homogenised
    press `state`), beside the section's superficial-core and lattice-interface profiles (kPa)."""
    from layerskin_exp.sim.config import SimConfig
    from layerskin_exp.sim.fem_reference.compare import DATA

    ref = np.load(DATA / "homogenised.npz", allow_pickle=True)
    st = section_stack(SimConfig())
    cx, cp, cw = ref["contact_x_mm"][state], ref["contact_kpa"][state], ref["contact_w_mm"]
    on = np.isfinite(cx)
    x = np.arange(-150.0, 150.0, dx)
    load = np.zeros_like(x)  # the section's nodal contact forces, each in its grid cell
    np.add.at(load, np.round((cx[on] - x[0]) / dx).astype(int), cp[on] * cw[on] / dx)
    lay = line_load_response(st, x, load, None, [st.depth_of("core"), st.depth_of("lattice", 1.0)])
    at = np.array([0.0, 0.4, 1.0, 1.4, 2.0, 3.0, 6.0])
    return {"x_mm": at, "fz_n_per_mm": float(ref["fz_n_per_mm"][state]),
            "superficial_section": np.interp(at, ref["superficial_x_mm"], ref["superficial_kpa"][state]),
            "superficial_layered": np.interp(at, x, lay[0]),
            "interface_section": np.interp(at, ref["interface_x_mm"], ref["interface_kpa"][state]),
            "interface_layered": np.interp(at, x, lay[1])}


if __name__ == "__main__":
    for s in (0, 1):
        r = compare_with_section(s)
        print(f"section press {s} ({r['fz_n_per_mm']:.4f} N/mm), kPa at x = {', '.join(f'{v:g}' for v in r['x_mm'])} mm")
        for k in ("superficial_section", "superficial_layered", "interface_section", "interface_layered"):
            print(f"  {k:22s}" + "".join(f"{v:8.2f}" for v in r[k]))
