"""Report figures stay readable: axes set by the data's bulk, events apart from the score."""

import numpy as np

from analysis import study
from analysis.figures import force_figure, plt, slip_figure


def test_a_score_spike_does_not_stretch_the_slip_axis_and_events_have_their_own_strip():
    t = np.linspace(0, 10, 2000)
    score = np.sin(t * 7)
    score[1000] = 400.0  # one spike, as on the demo's torsion trial
    truth = np.linspace(0.1, 9.9, 80)
    det = truth[::2] + 0.01
    fig = slip_figure(t, score, truth, det, np.arange(det.size), np.arange(1, 80, 2), 3.0, "torsion")
    events, ax = fig.axes
    assert ax.get_ylim()[1] < 10 and ax.get_ylim()[1] > 3.0  # threshold visible, spike clipped
    assert ax.get_ylabel() == "cue score (MAD units)"
    assert ax.get_ylim()[0] <= -1.0
    assert not ax.get_lines()[0].get_ydata().max() > ax.get_ylim()[1]
    assert np.ptp(events.collections[0].get_segments()[0][:, 1]) < 1.0  # short truth ticks, not full-height lines
    fig.canvas.draw()
    legend = fig.legends[0]
    assert legend.get_window_extent().x0 >= ax.get_window_extent().x1  # outside, right of the plot
    plt.close(fig)


def test_force_figure_has_every_model_a_colourbar_scores_and_the_study_range():
    rng = np.random.default_rng(0)
    ref = rng.normal(0, 1, (300, 3))
    preds = {m: ref + rng.normal(0, 0.1, ref.shape) for m in ("linear", "T-s5", "S-s5", "D-s5")}
    scores = {m: {ax: {"r2": 0.5, "mae": 0.25} for ax in ("Fx", "Fy", "Fz")} for m in preds}
    fig = force_figure(ref, preds, np.linspace(0, 1, 300), scores, study.FORCE_RANGE_N)
    panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    assert len(panels) == 12 and len(fig.axes) == 13
    assert all("R² 0.500" in a.texts[0].get_text() and "MAE 0.250 N" in a.texts[0].get_text() for a in panels)
    assert {a.get_title().split(":")[0] for a in panels} == set(preds)
    assert panels[0].get_xlim()[0] < -2.0 and panels[0].get_xlim()[1] > 2.0  # the study's ±2 N is in view
    plt.close(fig)


def test_characterization_figure_shows_ramps_cop_shift_and_heights_beside_the_study():
    from analysis.characterization import PressTrial
    from analysis.figures import characterization_figure

    rng = np.random.default_rng(1)
    load = np.linspace(0.0, 5.0, 200)
    presses = [PressTrial(pos, load, 1e4 * (1 + 0.1 * pos) * np.sqrt(load)) for pos in range(4) for _ in range(2)]
    shear = [np.linspace(0.0, 2.05, 300) for _ in range(5)]
    dcs = [np.column_stack([0.9 * s + rng.normal(0, 0.1, s.size), rng.normal(0, 0.1, s.size)]) for s in shear]
    heights = {"bins": [{"fz_low_n": lo, "fz_high_n": lo + 1.0, "h_x_mm": 1.0 + lo, "h_y_mm": 2.0 + lo,
                         "r2_x": 0.5, "r2_y": 0.8} for lo in (1.0, 2.0, 3.0)]}
    fig = characterization_figure(presses, shear, dcs, heights, 2.0, (1.9, 2.1),
                                  {**study.CHARACTERIZATION, "heights": study.HEIGHTS})
    ramps, shift, height = fig.axes
    assert len(ramps.get_lines()) == len(presses) + 1  # one ramp per press and the matched-load line
    assert "CV 0.145" in ramps.get_title()
    labels = shift.get_legend_handles_labels()[1]
    assert "study" in labels and any(lb.startswith("ours") for lb in labels)
    assert {"ours h_x", "ours h_y", "study h_x", "study h_y"} <= set(height.get_legend_handles_labels()[1])
    plt.close(fig)
