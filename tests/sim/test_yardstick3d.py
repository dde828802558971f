"""The fast hemisphere against the 3D half-model of the study's geometry (fem_reference.yardstick3d):
the shear signals at the 3D model's three loads, and what the comparison catches."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import load_sim
from layerskin_exp.sim.fem_reference import yardstick3d as y3
from layerskin_exp.sim.fem_reference.compare import load_tolerances

TOL = load_tolerances()["yardstick3d"]["difference"]


@pytest.fixture(scope="module")
def sides():
    """{state label: (3D values, fast values)} at every 3D state of both designs, and the nominal
    design's model and its unloaded state."""
    from layerskin_exp.sim.fem_reference.shear3d import stiff_cover_sim

    sim = load_sim([])
    out, nominal = {}, None
    for design, states in ((sim, y3.STATES), (stiff_cover_sim(sim), y3.STIFF_STATES)):
        model = y3.fast_model(design)
        fresh = model.mech_state()
        nominal = nominal or (model, fresh)
        for label, name, depth in states:
            fem = y3.fem3d_side(label, name, depth, model)
            out[label] = (fem, y3.fast_side(model, fresh, fem["fz_n"], fem["ft_n"]))
    return out, *nominal


@pytest.mark.parametrize("label", [s[0] for s in (*y3.STATES, *y3.STIFF_STATES)])
def test_the_deep_count_cop_travels_as_the_3d_models_at_each_load(sides, label):
    fem, fast = sides[0][label]
    assert abs(fast["deep_cop_counts_mm"] - fem["deep_cop_counts_mm"]) <= TOL["deep_cop_counts_mm"]


@pytest.mark.parametrize("label", [s[0] for s in (*y3.STATES, *y3.STIFF_STATES)])
def test_the_interlayer_shift_agrees_with_the_3d_models_at_each_load(sides, label):
    fem, fast = sides[0][label]
    assert abs(fast["interlayer_shift_counts_mm"] - fem["interlayer_shift_counts_mm"]) \
        <= TOL["interlayer_shift_counts_mm"]


@pytest.mark.parametrize("label", [s[0] for s in (*y3.STATES, *y3.STIFF_STATES)])
def test_each_gated_3d_reading_carries_the_load(sides, label):
    """A reading is a yardstick only if it passes its own balance: the pressure the gate reads
    from each 3D layer sums to F_z (twice the half-model's) within the solve's BALANCE_TOL, at the
    press and at the sheared state. The merged sheet's mid-plane along its normal does not (0.47 /
    0.92 / 2.01 / 1.94 of F_z too much), which is why the faces' mean is gated instead."""
    from layerskin_exp.sim.fem_reference.shear3d import BALANCE_TOL

    fem = sides[0][label][0]
    assert fem["deep_balance"] <= BALANCE_TOL
    assert fem["superficial_balance"] <= BALANCE_TOL
    assert fem["superficial_mid_plane_balance"] > 20 * BALANCE_TOL


def test_the_fast_deep_force_cop_meets_statics(sides):
    # x_cap + F_x H / F_z over the whole pad and what its sides carry (0.03 mm at worst)
    for label, (_, fast) in sides[0].items():
        assert fast["deep_force_cop_mm"] == pytest.approx(fast["deep_force_cop_statics_mm"], abs=0.1), label


def test_the_fast_statics_check_sees_the_sides_route_dropped(sides, monkeypatch):
    """Injection: the lattice's route at the pad's sides taken out (kernel and tables): the deep
    force CoP misses x_cap + F_x H / F_z by about F_t h_L / F_z (0.8 mm at 0.22 N)."""
    _, model, fresh = sides
    fem = sides[0]["0.22 N"][0]
    edge = model._edge.copy()
    monkeypatch.setattr(model.tab, "edge_deep_kpa", np.zeros_like(model.tab.edge_deep_kpa))
    try:
        model._edge[:] = 0.0
        fast = y3.fast_side(model, fresh, fem["fz_n"], fem["ft_n"])
    finally:
        model._edge[:] = edge
    assert abs(fast["deep_force_cop_mm"] - fast["deep_force_cop_statics_mm"]) > 0.1


@pytest.mark.parametrize("label", [
    pytest.param("0.22 N", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: the 3D deep force CoP travels 1.70 mm against x_cap + F_x H / F_z = 1.41 (0.29 beyond the "
        "mesh error's 0.28): the contact's force centroid leads the cap's axis by 0.23 mm (load_x 0.76 at cap "
        "x 0.54; the moment balance about the actual load point holds within 1e-4)"))),
    "0.83 N", "3 N", "stiff cover 3 N"])
def test_the_3d_deep_force_cop_meets_statics(sides, label):
    # x_cap + F_x H / F_z, within the 3D model's mesh error
    fem = sides[0][label][0]
    assert fem["deep_force_cop_mm"] == pytest.approx(fem["deep_force_cop_statics_mm"], abs=0.28)


@pytest.mark.parametrize("label", [
    "0.22 N",
    pytest.param("0.83 N", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: with the couple dropped the fast deep count CoP travels 0.76 mm against the 3D model's "
        "1.06 (0.99 without the error; band 0.48) and the shift is -0.10 against -0.23 (band 0.30): at "
        "F_t / F_z 0.20 the cap's own travel (1.0 mm, the cover's shear) carries most of the deep CoP's, "
        "the couple's lever F_t H / F_z adds 0.5 mm of force CoP of which the counts see 0.2"))),
    pytest.param("3 N", marks=pytest.mark.xfail(strict=True, reason=(
        "measured: with the couple dropped the deep count CoP travels 0.61 mm against 0.66 with it and the "
        "3D model's 0.62, the shift -0.06 against -0.07 and the 3D -0.12 mm (bands 0.48, 0.30): at F_t / F_z "
        "0.082, the 3D branch's reach, the lever F_t H / F_z is 0.24 mm of force CoP and the counts of the "
        "peak 8 times the 3D model's see almost none of it"))),
])
def test_dropping_the_tangential_loads_moment_fails_the_deep_rows(sides, label):
    """Injection: the couple of the shear about the deep plane removed from the fast model (its
    tables' couple responses and the lattice's route at the pad's sides zeroed): the deep count CoP
    then moves only with the cap's ground position, and the comparison must refuse it."""
    _, model, fresh = sides
    lk, edge = model._lk.copy(), model._edge.copy()
    try:
        model._lk[..., 2:4] = 0.0
        model._edge[:] = 0.0
        fem = sides[0][label][0]
        fast = y3.fast_side(model, fresh, fem["fz_n"], fem["ft_n"])
    finally:
        model._lk[:], model._edge[:] = lk, edge
    assert abs(fast["deep_cop_counts_mm"] - fem["deep_cop_counts_mm"]) > TOL["deep_cop_counts_mm"] \
        or abs(fast["interlayer_shift_counts_mm"] - fem["interlayer_shift_counts_mm"]) > TOL["interlayer_shift_counts_mm"]


def test_the_deep_pattern_at_the_columns_feet_fails_the_deep_rows(sides, monkeypatch):
    """Injection: the deep pattern left at the columns' feet (the sheet's travel not added to its
    position, as before), the moment F_z u with nowhere to go: the deep count CoP falls short where
    the sheet travels enough to tell, the stiff cover's state (1.5 mm in 3D; at the nominal design's
    0.25 mm at 0.83 N and 0.11 mm at 0.22 N it is inside the band)."""
    from layerskin_exp.sim.fem_reference.shear3d import stiff_cover_sim

    model = y3.fast_model(stiff_cover_sim(load_sim([])))
    fresh = model.mech_state()
    fem = sides[0]["stiff cover 3 N"][0]
    real = model.step_many

    def feet(t, xyz, yaw):
        recs = real(t, xyz, yaw)
        recs[:, 9:11] = 0.0  # no travel in the frame pipeline: the deep pattern sits under the sheet's point
        return recs

    monkeypatch.setattr(model, "step_many", feet)
    fast = y3.fast_side(model, fresh, fem["fz_n"], fem["ft_n"])
    assert abs(fast["deep_cop_counts_mm"] - fem["deep_cop_counts_mm"]) > TOL["deep_cop_counts_mm"]


def test_the_gate_refuses_a_state_the_fast_model_cannot_reach_sticking(sides):
    _, model, fresh = sides
    with pytest.raises(ValueError, match="did not reach F_x"):
        y3.fast_side(model, fresh, 0.3, 5.0)
    assert np.isfinite(sides[0]["0.22 N"][1]["tangential_stiffness"])


def test_a_design_without_its_3d_data_fails_the_gate(tmp_path):
    """Both designs are gated: with the stiff cover's 3D data missing its rows are there and fail
    (validate cannot pass on the nominal design alone), and the record says what to run."""
    from layerskin_exp.sim.fem_reference.compare import DATA

    for name in ("shear3d", "shear3d_mid_branch", "shear3d_load_branch"):
        (tmp_path / f"{name}.npz").symlink_to(DATA / f"{name}.npz")
    rows, record = y3.rows(load_sim([]), data=tmp_path)
    stiff = [r for r in rows if r.load.startswith("stiff cover")]
    assert len(stiff) == len(y3.GATED_DIFFERENCE) + len(y3.GATED_RATIO)
    assert not any(r.passed for r in stiff)
    assert "--stiff-cover" in record["stiff cover 3 N"]["error"]


@pytest.mark.parametrize("label", [s[0] for s in (*y3.STATES, *y3.STIFF_STATES)])
def test_every_3d_state_reports_the_sheets_mid_plane_reading(sides, label):
    """The committed 3D data carry the superficial sheet's faces (shear3d.Stack3D.line_z), so the
    gate reads their mean and the merged sheet's mid-plane is reported beside it; it is a different
    reading, not a copy of it."""
    fem = sides[0][label][0]
    for row in ("superficial_cop_counts", "interlayer_shift_counts"):
        assert np.isfinite(fem[f"{row}_mid_plane_mm"])
    assert fem["superficial_cop_counts_mid_plane_mm"] != fem["superficial_cop_counts_mm"]


def test_the_3d_layers_are_read_along_the_sheets_normal(sides, tmp_path):
    """The gated 3D reading is the pressure along each sheet's normal where it is now
    (shear3d.Stack3D.plane_normals). Read from the z component instead (the committed 3 N branch
    with its normal readings taken out), the mid-plane's superficial count CoP travels 0.4 mm
    further: the force through the tilted mid-plane carries the sheet's transverse shear force
    times its slope, which no FSR reads; the faces' mean moves by 0.02 mm."""
    from layerskin_exp.sim.fem_reference.compare import DATA, load_fem

    _, model, _ = sides
    label, name, depth = y3.STATES[2]
    res = load_fem(name)
    assert "superficial_normal_kpa" in res
    np.savez(tmp_path / f"{name}.npz", **{k: v for k, v in res.items() if not k.endswith("_normal_kpa")})
    along_z = y3.fem3d_side(label, name, depth, model, tmp_path)
    normal = y3.fem3d_side(label, name, depth, model, DATA)
    assert normal == sides[0][label][0]
    assert along_z["superficial_cop_counts_mid_plane_mm"] - normal["superficial_cop_counts_mid_plane_mm"] > 0.3
    # the faces lie against the soft cover and lattice, which carry little in their plane
    assert abs(along_z["superficial_cop_counts_mm"] - normal["superficial_cop_counts_mm"]) < 0.1
    assert abs(along_z["deep_cop_counts_mm"] - normal["deep_cop_counts_mm"]) < 0.01  # the deep sheet lies flat


@pytest.mark.parametrize("label", [s[0] for s in (*y3.STATES, *y3.STIFF_STATES)])
def test_every_state_reports_the_superficial_asymmetry_on_both_sides(sides, label):
    """Reported, not gated (its 3D value is not converged through the cover: tolerances.yaml); read
    about the sheet's point under the cap on each side, so a state against itself reads 0."""
    fem, fast = sides[0][label]
    assert np.isfinite(fem["superficial_asymmetry_counts"]) and np.isfinite(fast["superficial_asymmetry_counts"])
    assert "superficial_asymmetry_counts" in y3.REPORTED
    assert "superficial_asymmetry_counts" not in (*y3.GATED_DIFFERENCE, *y3.GATED_RATIO)


def test_the_asymmetry_is_read_about_the_point_it_is_given():
    """A press against itself reads no asymmetry; read about a point a pitch further on, the same
    map reads its counts behind that point."""
    from layerskin_exp.sim.fem_reference.compare import SKIN

    counts = np.zeros((2, 16, 16))
    counts[:, 6:10, 6:10] = 100.0
    x = float(SKIN.taxel_centres_mm()[8])
    assert y3._count_rows(counts, counts, x, x)["superficial_asymmetry_counts"] == 0.0
    assert y3._count_rows(counts, counts, x, x + 1.5)["superficial_asymmetry_counts"] < -0.4
