"""Physical errors injected into the fast model, shared by the tests that show a comparison with
the finite-element reference sees them (tests/sim/test_fem_reference.py, test_fem_shear3d.py)."""

from __future__ import annotations

from dataclasses import replace

from layerskin_exp.sim import skin


def _inject_fixed_cover_width(monkeypatch):
    from layerskin_exp.sim import contact

    monkeypatch.setattr(contact, "contact_confinement_mm", lambda *a: 2.0)


def _inject_rigid_cover(monkeypatch):
    """The cover's tangential path removed: the sheet follows the cap wholly."""
    from layerskin_exp.sim import laminate

    monkeypatch.setattr(laminate.PlateOnFoundation, "traction_stiffness", lambda self, sol: 0.0)


def _inject_stiff_spacer_shear(monkeypatch):
    law = skin.SpacerLaw.shear_stiffness_kpa_per_mm
    monkeypatch.setattr(skin.SpacerLaw, "shear_stiffness_kpa_per_mm", lambda self, c: 10.0 * law(self, c))


def _stiff_sheet(fsim):
    return replace(fsim, sheet=replace(fsim.sheet, film_modulus_mpa=100.0 * fsim.sheet.film_modulus_mpa))


# physical error -> (how it is injected: a monkeypatch or a design hook, the metrics that must see it)
INJECTIONS = {
    # With the bands widened by the reference's own mesh error (fem_reference/tolerances.yaml,
    # discretisation), two rows no longer see an error alone: the peak superficial pressure moves
    # 1.46-1.55x under the fixed cover width (band up to 1.59x) and the effective height 0.64-0.77x
    # under the 10x stiff lattice (band down to 0.52x); contact width and tangential stiffness do.
    # A finer reference narrows those bands again.
    "cover squeezed over a fixed 2 mm": (_inject_fixed_cover_width, None, ("contact_width",)),
    "cover rigid in shear": (_inject_rigid_cover, None, ("sheet_share_of_travel",)),
    "lattice 10x too stiff in shear": (_inject_stiff_spacer_shear, None, ("tangential_stiffness",)),
    # Not the inter-layer count shift: where the sheet hands the shear's couple to the lattice over
    # the whole pad (laminate.PlateOnFoundation.couple), the couple's pressure lies spread over the
    # pad, where the counts hardly see it, so the count shift does not follow the sheet's
    # rigidity (nor, below, the lattice's shear stiffness); the rows listed do. Not the deep count
    # CoP since 170b76d: half of the lattice's moment goes straight onto the deep sheet, bypassing
    # the sheet's bending, and the deep CoP moves 0.19 / 0.10 mm under this error (band 0.2).
    "sheet 100x too stiff in bending": (None, _stiff_sheet, ("peak_deep_taxel_kpa", "effective_height_rise")),
}
