"""The count-CoP shear signals over alignments of cap, walls and taxels
(layerskin_exp.sim.fem_reference.alignment): the committed runs balance their load, and at the
committed section's own alignment (cap on the centre wall, midway between two taxels) the
alignment reader gives back what the comparison reads."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference import __main__ as regen
from layerskin_exp.sim.fem_reference import alignment as al
from layerskin_exp.sim.fem_reference import compare as fc

SIM = SimConfig()


@pytest.fixture(scope="module")
def model():
    return fc.line_model(fc.line_sim(SIM, "bonded"))


@pytest.mark.parametrize("x0", al.ALIGN_X0_MM[1:])
def test_each_alignment_run_carries_the_load_and_starts_where_it_says(x0):
    fem = fc.load_fem(f"alignment/x0_{x0:.2f}")
    assert float(fem["cap_start_mm"]) == x0
    for line, b in regen.balance(fem).items():
        assert np.all(np.abs(b - 1.0) < 0.02), (line, b)
    press = (fem["phase"] == 0) & np.isclose(fem["depth_mm"], 0.3)
    assert np.allclose(fem["cap_x_mm"][press], x0)
    # both shear branches reach the comparison's ratio
    for b in (0.3, 0.6):
        on = (fem["phase"] == 1) & np.isclose(fem["branch_depth_mm"], b)
        assert (fem["fx_n_per_mm"][on] / fem["fz_n_per_mm"][on]).max() >= fc.SHEAR_RATIO


def test_the_committed_alignment_reads_as_the_comparison_does(model):
    """Cap at x = 0 on the centre wall, taxels at +-0.75 mm: the cap starts 0.75 mm from a taxel's
    centre, the grid where the comparison reads it. Each signal is the comparison's value less the
    press's own (the mesh leaves a centred press 0.03 mm of count offset at 0.6 mm); a grid placed
    a quarter pitch off reads 0.10 mm of inter-layer shift against 0.24 mm here."""
    fem = fc.load_fem("bonded")
    ours = al.fem_signals(fem, model, taxel_mm=0.75)
    reader = fc.Reader(model)
    rows = fc.fem_side(fem, reader, sorted(ours))
    for b, row in zip(sorted(ours), rows, strict=True):
        st = int(np.flatnonzero((fem["phase"] == 0) & np.isclose(fem["depth_mm"], b))[0])
        press = reader.counts(reader.maps(fem, fem["superficial_kpa"][st], fem["deep_kpa"][st]))
        cs, cd = fc._cop_x(press[0]), fc._cop_x(press[1])
        assert ours[b]["interlayer_shift_counts_mm"] == pytest.approx(row["interlayer_shift_counts_mm"] - (cs - cd), abs=1e-9)
        assert ours[b]["deep_cop_counts_mm"] == pytest.approx(row["deep_cop_counts_mm"], abs=1e-9)
        assert ours[b]["superficial_offset_counts_mm"] == pytest.approx(row["superficial_offset_counts_mm"] - cs, abs=1e-9)


def test_the_taxel_alignment_moves_the_grid_not_the_load(model):
    """A reader whose grid is shifted by a whole pitch reads the same counts one column over."""
    fem = fc.load_fem("bonded")
    st = int(np.flatnonzero(fem["phase"] == 0)[0])
    a = fc.Reader(model).maps(fem, fem["superficial_kpa"][st], fem["deep_kpa"][st])
    b = fc.Reader(model, shift_mm=fc.SKIN.pitch_mm).maps(fem, fem["superficial_kpa"][st], fem["deep_kpa"][st])
    assert np.allclose(a[:, :, 1:], b[:, :, :-1], atol=1e-9)
    assert not np.allclose(a, b)
