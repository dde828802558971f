"""The lattice's shear stiffness under compression: what the 3D model's own lattice fields say
under the cap, and the fast model's shear law (spacer.SpacerLaw.shear_stiffness_kpa_per_mm)
beside them."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import load_sim
from layerskin_exp.sim.fem_reference.compare import DATA
from layerskin_exp.sim.spacer import SpacerLaw

SIM = load_sim([])
LAW = SpacerLaw(SIM.spacer)
H = SIM.spacer.thickness_mm


def _lattice_fields(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The 3D lattice's local compression at the press and its tangent shear stiffness per area
    (kPa/mm) from the press to the branch's last sheared state, at the nodes on the shear's line
    within 1.5 mm of the cap's axis: the shear traction's change on the lattice's base over the
    change of the relative travel of its two faces."""
    with np.load(DATA / f"{name}.npz") as z:
        phase = z["phase"]
        i0, i1 = int(np.flatnonzero(phase == 0)[-1]), len(phase) - 1
        xy = z["interface_xy_mm"]
        top, base = z["sheet_bottom_u_mm"].astype(float), z["interface_u_mm"].astype(float)
        tau = z["interface_shear_kpa"].astype(float)
    on = (np.abs(xy[:, 1]) < 1e-9) & (np.abs(xy[:, 0]) <= 1.5 + 1e-9)
    e = (base[i0, on, 2] - top[i0, on, 2]) / H
    du = (top[i1, on, 0] - base[i1, on, 0]) - (top[i0, on, 0] - base[i0, on, 0])
    return e, np.abs(tau[i1, on] - tau[i0, on]) / np.abs(du)


def _ratio(law, name: str) -> np.ndarray:
    """The 3D field's stiffness over the law's at the same local compression, node by node."""
    e, k3 = _lattice_fields(name)
    return k3 / law(e * H)


def _open_lattice(compression_mm):
    """The open lattice sheared over its own height, G / h, at any compression."""
    return np.full_like(np.asarray(compression_mm, float), LAW.g_open_kpa / H)


def _current_height(compression_mm):
    """The open lattice sheared over its current height, G / (h (1 - e))."""
    e = np.clip(np.asarray(compression_mm, float) / H, 0.0, 0.95)
    return LAW.g_open_kpa / (H * (1.0 - e))


# The band: within a factor 2 of the 3D field at every node under the cap. Shearing over the
# current height differs from shearing over the lattice's own height by 1 / (1 - e), 2.5 at the 3 N
# branches' strain of 0.6, so the band tells the two laws apart without fitting either.
BAND = (0.5, 2.0)
BRANCHES = ["shear3d_mid_branch", "shear3d_load_branch", "shear3d_stiff_cover"]


@pytest.mark.parametrize("name", BRANCHES)
def test_the_3d_lattice_under_the_cap_shears_over_its_own_height(name):
    """The yardstick's lattice (a compressible neo-Hooke matrix, nu = 0, plus a term on the planes'
    separation that adds no shear) carries mu u / H under a through-thickness preload; its fields
    under the cap: 0.89-0.93 mu / H at 0.83 N (strain 0.19), 0.54-0.66 at 3 N and 0.86-0.93 with
    the stiff cover (strain 0.6)."""
    ratio = _ratio(_open_lattice, name)
    assert np.all((ratio >= BAND[0]) & (ratio <= BAND[1])), ratio


def test_the_field_check_refuses_shearing_over_the_current_height():
    ratio = _ratio(_current_height, "shear3d_load_branch")
    assert np.any(ratio < BAND[0]), ratio


@pytest.mark.parametrize("name", [
    "shear3d_mid_branch",
    pytest.param("shear3d_load_branch", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: the fast law under the cap at 3 N (strain 0.58-0.60) is 2.2-3.3 times the 3D field "
        "(ratio 0.30-0.46; with G / h(1 - e) for the open lattice it was 4.3-6.3): its walls start to touch "
        "there (densification strain 0.5625) and the squeezed solid shears over the gap left, which the 3D "
        "lattice has no walls to do"))),
    pytest.param("shear3d_stiff_cover", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: 1.6-2.1 times the 3D field (ratio 0.48-0.64) under the stiff cover at 3 N (3.0-3.8 "
        "with G / h(1 - e) for the open lattice), the walls touching as with the nominal cover"))),
])
def test_the_fast_shear_law_under_the_cap_is_the_3d_lattices(name):
    ratio = _ratio(LAW.shear_stiffness_kpa_per_mm, name)
    assert np.all((ratio >= BAND[0]) & (ratio <= BAND[1])), ratio
