"""The 3D half-model of the hemisphere's press and shear (layerskin_exp.sim.fem_reference.shear3d):
its homogenised lattice against the honeycomb's closed forms (Gibson & Ashby 1997, sec. 4.4:
E3 = rho E_s, G13 = rho G_s / 2; the same 5 % and 15 % as tests/sim/test_fem_closed_forms.py),
and the committed 3D data's balance: every layer's 2 sum(p A) equals F_z within 2 %, a check
that fails on an injected extraction error."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference import model as fe_model
from layerskin_exp.sim.fem_reference import shear3d as s3
from layerskin_exp.sim.fem_reference.model import KPA, Section

SEC = Section.from_sim(SimConfig())


def _stress_kpa(F: np.ndarray) -> np.ndarray:
    """The homogenised lattice's first Piola stress (kPa) at one deformation gradient."""
    umat = s3.lattice_material(SEC)
    P = umat.gradient([F.reshape(3, 3, 1, 1), None])[0]
    return P[..., 0, 0] / KPA


def lattice_moduli3d(strain: float = 0.01) -> tuple[float, float]:
    """(E3, G13) in kPa: uniaxial stress along z (laterally free) and simple shear in xz."""
    F = np.eye(3)
    F[2, 2] = 1.0 - strain
    e3 = -_stress_kpa(F)[2, 2] / strain
    F = np.eye(3)
    F[0, 2] = strain
    g13 = _stress_kpa(F)[0, 2] / strain
    return float(e3), float(g13)


def test_the_homogenised_lattice_meets_the_honeycombs_moduli():
    e3, g13 = lattice_moduli3d()
    e_hc, g_hc = SEC.honeycomb_moduli_kpa()
    assert e3 == pytest.approx(e_hc, rel=0.05), (e3, e_hc)
    assert g13 == pytest.approx(g_hc, rel=0.15), (g13, g_hc)


def test_the_moduli_check_sees_a_missing_fibre(monkeypatch):
    """Without its fibre term the layer is the matrix alone (E = 2 G13): the check must fail."""
    monkeypatch.setattr(fe_model, "lattice_constants", lambda sec: {"mu": sec.honeycomb_moduli_kpa()[1] * KPA,
                                                             "bulk": 0.0, "k": 0.0})
    e3, _ = lattice_moduli3d()
    assert e3 != pytest.approx(SEC.honeycomb_moduli_kpa()[0], rel=0.05)


def test_the_merged_sheet_bends_like_the_laminate():
    """One layer of the sheet's thickness with E = merged_sheet_e_mpa has the laminate's D."""
    e = s3.merged_sheet_e_mpa(SEC)
    t = 2 * SEC.film_mm + SEC.core_mm
    ef = 0.5 * (SEC.film_along_e_mpa + SEC.film_across_e_mpa)
    # the laminate's bending stiffness about its mid-plane, by the integral of E z^2
    z = np.linspace(-t / 2, t / 2, 200001)
    ez = np.where(np.abs(z) > SEC.core_mm / 2, ef, SEC.core_e_mpa)
    d_lam = float(np.sum(ez * z ** 2) * (z[1] - z[0]))
    assert e * t ** 3 / 12 == pytest.approx(d_lam, rel=1e-3)


@pytest.fixture(scope="module")
def committed():
    path = s3.DATA / "shear3d.npz"
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def test_every_layer_of_the_3d_data_carries_the_load(committed):
    bal = s3.balance3d(committed)
    assert set(bal) == {"superficial", "deep", "interface", "base", "contact"}
    assert len(committed["phase"]) >= 2
    for line, b in bal.items():
        assert np.all(np.abs(b - 1.0) < s3.BALANCE_TOL), (line, b)


def test_the_3d_balance_sees_an_extraction_error(committed):
    """Areas from the corner nodes' spacing alone (a bilinear lumping, mid-side nodes given the
    same share as corners) break the balance of the deep layer's map."""
    bad = dict(committed)
    w = np.asarray(committed["deep_w_mm2"], float)
    bad["deep_w_mm2"] = np.full_like(w, w.sum() / len(w))
    with pytest.raises(RuntimeError, match="does not carry the load"):
        s3.require_balance3d(bad, log=lambda *_: None)


def test_the_3d_data_was_sheared():
    """Each branch the committed 3D data starts is sheared along +x with F_x along the travel."""
    with np.load(s3.DATA / "shear3d.npz") as z:
        phase, fx, x = z["phase"], z["fx_n"], z["cap_x_mm"]
    sheared = phase == 1
    assert sheared.any()
    assert np.all(fx[sheared] > 0) and np.all(x[sheared] > 0)
