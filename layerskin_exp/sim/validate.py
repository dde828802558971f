"""Physics validation of the simulated skin, as a command: the checks of
`layerskin_exp.sim.physics_checks` (closed forms, bounds, the FEM reference) as a table, then the
results read from counts.

    python -m layerskin_exp.sim.validate            # prints the table
    python -m layerskin_exp.sim.validate sim.spacer.modulus_kpa=20   # the same for another design

A Hydra app on conf/validate.yaml (the simulated world; started by layerskin_exp.cli.run_command,
like the protocols): sim.* overrides are checked as the protocols check them; exit code 1 if a
check fails. The physics loads only when the checks run, not for --help or a refused command line.
"""

from __future__ import annotations

import sys

from layerskin_exp.cli import hydra_main, run_command


def report(sim) -> int:
    """Print the table and the results for `sim` (SimConfig); 0 if every check passed, else 1."""
    from layerskin_exp.sim.physics_checks import run, table

    checks, extra = run(sim)
    print(table(checks))
    section = extra.get("section_checks")
    if section:
        print("\nDiagnostics, gating nothing: the plane-strain section (what its walls and plane strain do to "
              "each row; fem_reference.alignment)")
        print(table(section))
    for line in extra.get("fem_record", {}).get("disjoint", []):
        print(f"no fast value passes both sections: {line}")
    mid = _mid_plane_lines(extra.get("yardstick3d_record", {}))
    if mid:
        print("\nReported, gating nothing: the 3D superficial reading from the merged sheet's mid-plane along "
              "its normal, which does not carry the load it reads, beside the gated mean of the sheet's two "
              "faces and the fast model's")
        print("\n".join(mid))
    for k, v in extra.items():
        if k in ("fem_record", "section_checks", "yardstick3d_record"):
            continue
        print(f"{k}: {v}")
    return 0 if all(c.passed for c in checks) else 1


def _mid_plane_lines(record: dict) -> list[str]:
    lines = []
    for label, rec in record.items():
        fem, fast = rec.get("3d"), rec.get("fast")
        if not fem or not fast or "superficial_cop_counts_mid_plane_mm" not in fem:
            continue
        for row in ("superficial_cop_counts", "interlayer_shift_counts"):
            lines.append(f"3D: {row}_mm at {label}: mid-plane {fem[row + '_mid_plane_mm']:.3g} "
                         f"(carries {1 + fem['superficial_mid_plane_balance']:.2f} F_z), faces' mean "
                         f"{fem[row + '_mm']:.3g}, fast {fast[row + '_mm']:.3g}")
    return lines


@hydra_main("validate")
def main(cfg) -> None:
    from layerskin_exp.config import validate

    code = report(validate(cfg).sim)
    if code:
        sys.exit(code)


def cli() -> None:
    """`python -m layerskin_exp.sim.validate`: --help, the whole command line refused or run."""
    import layerskin_exp.sim.config  # noqa: F401 - stores the world's sim and skin schemas

    run_command("validate", lambda: main)


if __name__ == "__main__":
    cli()
