"""Look at the simulated skin: both layers' counts under a press and under a slide.

    python -m layerskin_exp.sim.preview [out=PATH] [seed=N] [sim.KEY=VALUE ...] [skin.KEY=VALUE ...]
    python -m layerskin_exp.sim.preview out=soft.png sim.spacer.modulus_kpa=20

A Hydra app on conf/preview.yaml (started by layerskin_exp.cli.run_command, like the protocols):
sim.* and skin.* are the same overrides the protocols take (conf/sim/, conf/skin/), checked the
same way; seed=N seeds the model (sim.seed for this preview); --help and --cfg job answer. Writes a 2x2 PNG (rows: press, slide; columns: superficial, deep) with each layer's centre of
pressure marked (baseline-subtracted counts as weights) and the applied force in the titles.
"""

from __future__ import annotations

from layerskin_exp.cli import hydra_main, run_command


def render(out: str = "skin_preview.png", seed: int = 0, sim=None, skin=None) -> str:
    """Write the preview PNG to `out`; sim (SimConfig) / skin (SkinConfig) default to the defaults
    with sim.seed = seed."""
    import matplotlib
    import numpy as np

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


@hydra_main("preview")
def main(cfg) -> None:
    from dataclasses import replace

    from layerskin_exp.config import validate

    typed = validate(cfg)  # run_command has refused a bad command line: this only builds the objects
    sim = typed.sim if typed.seed is None else replace(typed.sim, seed=typed.seed)
    print(f"wrote {render(typed.out, sim=sim, skin=typed.skin)}")


def cli() -> None:
    """`python -m layerskin_exp.sim.preview`: --help, the whole command line refused or run."""
    import layerskin_exp.sim.config  # noqa: F401 - stores the preview, sim and skin schemas

    run_command("preview", lambda: main)


if __name__ == "__main__":
    cli()
