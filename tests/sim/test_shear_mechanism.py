"""The shear's couple in the fast model comes from the stack's mechanics (issue 29): the cover's
lever acts under the contact, the lattice's is handed over the pad by the in-plane-stiff sheet and
loads it at the pad's edge; the couple's pressures balance its moment; the deep pattern stays where
the loaded lattice columns stand (their feet) instead of following the cap."""

import numpy as np
import pytest

from layerskin_exp.sim import laminate
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import _solver

SIM = SimConfig()
EDGE_BAND_MM = 2.0  # the pad's outer band (the section's pad: 13 mm half-width; the lattice 2.5 mm high)


def _moment(plate, resp) -> float:
    return plate.first_moment(resp.foundation_kpa) - plate.first_moment(resp.contact_kpa)


@pytest.mark.parametrize("kind, depth", [("rod", 0.3), ("rod", 1.0), ("hemisphere", 0.8)])
@pytest.mark.parametrize("share", [0.0, 0.5, 0.9, 1.0])
def test_the_couple_balances_its_moment_whatever_the_levers(kind, depth, share):
    plate = _solver(SIM, kind)
    sol = plate.solve(depth)
    assert _moment(plate, plate.couple(sol, share)) == pytest.approx(1.0, abs=1e-2)


def test_without_the_walls_shear_the_lattices_part_loses_its_balance(monkeypatch):
    """The lattice's reaction near the pad's edge is partly its walls' shear (the operator's
    Pasternak part): left out, the couple handed to the lattice no longer balances."""
    plate = _solver(SIM, "rod")
    sol = plate.solve(0.5)
    assert _moment(plate, plate.couple(sol, 1.0)) == pytest.approx(1.0, abs=1e-2)
    monkeypatch.setattr(laminate.PlateOnFoundation, "_lattice_m1", lambda self, w1, slope: slope * w1)
    assert _moment(plate, plate.couple(sol, 1.0)) != pytest.approx(1.0, abs=1e-2)


@pytest.mark.parametrize("depth", [0.3, 0.6, 1.0])
def test_the_lattices_part_lies_at_the_pads_edge_and_the_covers_under_the_contact(depth):
    plate = _solver(SIM, "rod")
    sol = plate.solve(depth)
    x = plate.x
    edge = np.abs(x) >= plate.pad_radius - EDGE_BAND_MM
    near = np.abs(x) <= 4.0

    def share_of_moment(resp, where):
        return plate.first_moment(np.where(where, resp.foundation_kpa, 0.0)) / plate.first_moment(resp.foundation_kpa)

    lattice, cover = plate.couple(sol, 1.0), plate.couple(sol, 0.0)
    assert share_of_moment(lattice, edge) > 0.5
    assert abs(share_of_moment(lattice, near)) < 0.05
    # the cover's part stays near the contact: a couple placed there would fail the first check
    assert share_of_moment(cover, edge) < 0.1
    assert share_of_moment(cover, near) > 0.3


def test_the_couple_refuses_a_share_outside_0_1():
    plate = _solver(SIM, "rod")
    sol = plate.solve(0.5)
    with pytest.raises(ValueError, match="lattice_share=1.2"):
        plate.couple(sol, 1.2)


@pytest.mark.parametrize("kind", ["rod", "hemisphere"])
def test_the_deep_pattern_stays_at_the_columns_feet_whatever_the_sheets_travel(kind):
    """The sheet dragged 1 mm along x (no shear force, so no couple): the lattice columns' tops go
    with it and each column's load lands at its own foot, under the cap's point in the sheet's
    frame, so both layers' maps are those of the undragged sheet at that point. (With the deep
    pattern at the cap's ground position, the deep map would move by the sheet's travel.)"""
    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.skin import SkinModel

    radius = rig.INDENTER_RADIUS_MM if kind == "rod" else None
    model = SkinModel(SIM, SkinConfig(), kind, np.random.default_rng(0), contact_radius_mm=radius)
    depth = 0.6 if kind == "rod" else 1.0
    rec = model.step_many(np.array([0.0]), np.array([[0.4, 0.3, -depth]]), np.array([np.pi / 2]))[0]
    assert rec[mk.S_FZ] > 0 and rec[mk.S_FX] == 0.0
    dragged = rec.copy()
    dragged[mk.S_UX] += 1.0
    dragged[mk.S_SERIAL] = rec[mk.S_SERIAL] + 1000  # another configuration: no map reused
    still, moved = (np.stack(model.pressure_maps([model.state_of(r)])) for r in (rec, dragged))
    assert still[1].max() > 0
    np.testing.assert_allclose(moved, still, rtol=1e-6, atol=1e-6 * still.max())




@pytest.mark.parametrize("kind", ["rod", "hemisphere"])
def test_the_superficial_core_reads_the_mean_of_the_contact_and_the_lattice(kind):
    """The superficial FSR's core lies between the sheet's films: it reads half the load on the
    sheet's top (the contact) and half the lattice's reaction on its bottom, so its profile carries
    the whole load, as the deep layer's does (each equals the row's load by the laminate's own
    equilibrium). Reading either side alone, or both in full, breaks the balance by a factor."""
    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.skin import SkinModel

    radius = rig.INDENTER_RADIUS_MM if kind == "rod" else None
    tab = SkinModel(SIM, SkinConfig(), kind, np.random.default_rng(0), contact_radius_mm=radius).tab
    d = tab.dist_mm
    weight = np.gradient(d) if kind == "rod" else 2.0 * np.pi * d * np.gradient(d)  # mm or mm^2 per sample
    rows = [k for k in (10, 40, 80) if tab.load[k] > 0]
    assert len(rows) == 3
    for k in rows:
        assert tab.superficial_kpa[k] @ weight * 1e-3 == pytest.approx(tab.load[k], rel=1e-2)
        assert tab.deep_kpa[k] @ weight * 1e-3 == pytest.approx(tab.load[k], rel=1e-2)
        # where the cover's spread of the contact has died out (beyond the contact by five cover
        # thicknesses) the superficial core reads half the lattice's pressure (blurred alike)
        outside = np.abs(d) > tab.contact_halfwidth_mm[k] + 5.0 * SIM.cover.thickness_mm
        lattice_there = tab.deep_kpa[k][outside] @ weight[outside]
        assert lattice_there > 0.05 * (tab.deep_kpa[k] @ weight)  # a part worth checking
        assert tab.superficial_kpa[k][outside] @ weight[outside] == pytest.approx(0.5 * lattice_there, rel=1e-2)
