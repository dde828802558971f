"""Look at the simulated skin: both layers' counts under a press and under a slide.

    python -m layerskin_exp.sim.preview [out=PATH] [seed=N] [sim.KEY=VALUE ...] [skin.KEY=VALUE ...]
    python -m layerskin_exp.sim.preview out=soft.png sim.spacer.modulus_kpa=20

sim.* and skin.* are the same overrides the protocols take (conf/sim/, conf/skin/, composed by
conf/world.yaml), checked the same way; seed=N is sim.seed=N. Writes a 2x2 PNG (rows: press, slide; columns: superficial, deep) with each layer's centre of
pressure marked (baseline-subtracted counts as weights) and the applied force in the titles.
"""

from __future__ import annotations

import sys

import numpy as np


def render(out: str = "skin_preview.png", seed: int = 0, sim=None, skin=None) -> str:
    """Write the preview PNG to `out`; sim (SimConfig) / skin (SkinConfig) default to the defaults
    with sim.seed = seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.features import centre_of_pressure
    from layerskin_exp.sim.config import SimConfig
    from layerskin_exp.sim.skin import SkinModel

    sim = sim if sim is not None else SimConfig(seed=seed)
    skin = skin if skin is not None else SkinConfig()
    m = SkinModel(sim, skin, "hemisphere", np.random.default_rng(sim.seed))
    idle = m.frames([m.step(0.0, np.array([0.0, 0.0, 1.0]))], np.array([0.0]))
    cases = []
    t = 0.0
    for k in range(400):  # press to 2.2 mm at (-3, 1.5) mm, hold
        t = 0.001 * (k + 1)
        st = m.step(t, np.array([-3.0, 1.5, -2.2 * min(k / 300.0, 1.0)]))
    cases.append(("press", st, m.frames([st], np.array([t]))))
    for k in range(1500):  # slide +x at 2 mm/s
        t += 0.001
        st = m.step(t, np.array([-3.0 + 0.002 * (k + 1), 1.5, -2.2]))
    cases.append(("slide +x 3 mm", st, m.frames([st], np.array([t]))))

    half = rig.SENSING_HALF_WIDTH_MM
    fig, axes = plt.subplots(2, 2, figsize=(9, 8.5), constrained_layout=True)
    for row, (name, st, (sup, deep)) in enumerate(cases):
        for col, (layer, counts, base) in enumerate((("superficial", sup[0], idle[0][0]), ("deep", deep[0], idle[1][0]))):
            ax = axes[row, col]
            im = ax.imshow(counts, origin="lower", extent=(-half, half, -half, half), cmap="magma", vmin=0, vmax=rig.ADC_MAX)
            c = centre_of_pressure(np.clip(counts.astype(float) - base, 0.0, None), skin)
            ax.plot(*c, "c+", ms=14, mew=2, label=f"CoP ({c[0]:.2f}, {c[1]:.2f}) mm")
            ax.legend(loc="lower right", fontsize=8)
            f = st.force_n
            ax.set_title(f"{name}: {layer}\nF = ({f[0]:.2f}, {f[1]:.2f}, {f[2]:.2f}) N"
                         f"{'  slipping' if st.slipping else ''}", fontsize=9)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("y (mm)")
    fig.colorbar(im, ax=axes, shrink=0.6, label="ADC counts")
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def configs(overrides: list[str]):
    """(SimConfig, SkinConfig) from conf/world.yaml with sim.* / skin.* overrides, validated as the
    protocols validate them (a bad key or value exits with code 2 and one line)."""
    import layerskin_exp.sim.config  # noqa: F401 - stores the sim, skin and world schemas
    from layerskin_exp.config import ConfigError, compose, format_config_error

    try:
        typed = compose("world", overrides)
    except ConfigError as e:
        print(format_config_error(e), file=sys.stderr)
        sys.exit(2)
    return typed.sim, typed.skin


def main(argv: list[str]) -> None:
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__.strip())
        return
    out, overrides = "skin_preview.png", []
    for a in argv:
        key, sep, value = a.partition("=")
        if not sep or not (key in ("out", "seed") or key.lstrip("+~").startswith(("sim.", "skin."))):
            print(f"error: {a!r}: expected out=PATH, seed=N, sim.KEY=VALUE or skin.KEY=VALUE (see --help)",
                  file=sys.stderr)
            sys.exit(2)
        if key == "out":
            out = value
        else:
            overrides.append(f"sim.seed={value}" if key == "seed" else a)
    sim, skin = configs(overrides)
    path = render(out, sim=sim, skin=skin)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
