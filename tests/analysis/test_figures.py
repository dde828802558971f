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


def test_force_figure_carries_the_study_and_marks_unconverged_models():
    rng = np.random.default_rng(0)
    ref = rng.normal(0, 1, (200, 3))
    preds = {"linear": ref + 0.1, "T-s5": np.zeros_like(ref)}
    fig = force_figure(ref, preds, np.linspace(0, 1, 200), None, study.FORCE_RANGE_N, study.FORCE,
                       {"T-s5": "stopped at the epoch cap"})
    panels = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    lin, ts5 = (next(a for a in panels if a.get_title().startswith(m) and "Fx" in a.get_title())
                for m in ("linear", "T-s5"))
    assert "study: R² 0.474, MAE 0.275 N" in lin.texts[0].get_text()
    assert "study: R² 0.914, MAE 0.094 N" in ts5.texts[0].get_text()
    assert "NOT CONVERGED" in ts5.get_title() and "NOT CONVERGED" not in lin.get_title()
    plt.close(fig)


def test_tracking_figure_summarises_every_grip_depth_beside_the_study():
    from analysis.figures import tracking_figure

    ours = {layer: {f"{g}": {"a": 1.0 + 0.01 * g, "r2": 0.9, "mae": 0.2, "n_trials": 3} for g in (6, 9, 12, 15)}
            for layer in ("deep", "superficial")}
    fig = tracking_figure("translation", ours, study.TRACKING["translation"], "displacement (mm)")
    slope, r2, err = fig.axes
    lines = {ln.get_label(): ln for ln in slope.get_lines()}
    assert set(lines) == {"ours, deep", "study, deep", "ours, superficial", "study, superficial"}
    np.testing.assert_allclose(lines["study, deep"].get_ydata(), [1.35, 1.23, 1.22, 1.25])
    np.testing.assert_allclose(lines["ours, deep"].get_xdata(), [6, 9, 12, 15])
    assert "3 trials per grip depth" in fig._suptitle.get_text() and "/" not in slope.get_title()
    plt.close(fig)


def test_characterization_legends_cover_no_point_and_our_cv_is_beside_the_study():
    from analysis.characterization import PressTrial
    from analysis.figures import characterization_figure

    load = np.linspace(0.0, 5.0, 50)
    presses = [PressTrial(p, load, 1e4 * np.sqrt(load)) for p in range(3)]
    shear = [np.linspace(0.0, 2.05, 100)]
    dcs = [np.column_stack([np.linspace(0, 12, 100), np.zeros(100)])]  # points up to the top-left corner
    heights = {"bins": [{"fz_low_n": 0.5, "fz_high_n": 1.0, "h_x_mm": 9.5, "h_y_mm": 2.0, "r2_x": 0.5, "r2_y": 0.5}]}
    ours = {"uniformity": {"cv": 0.066, "ci_low": 0.037, "ci_high": 0.081, "n_positions": 3}}
    fig = characterization_figure(presses, shear, dcs, heights, 2.0, (1.9, 2.1),
                                  {**study.CHARACTERIZATION, "heights": study.HEIGHTS}, ours)
    fig.canvas.draw()
    ramps = fig.axes[0]
    assert "ours: CV 0.066 (0.037-0.081)" in ramps.get_title() and "study: CV 0.145 (0.125-0.162)" in ramps.get_title()
    for ax in fig.axes[1:]:
        leg = ax.get_legend().get_window_extent()
        assert leg.y1 <= ax.get_window_extent().y0  # below the plotting area: over no point
    plt.close(fig)


def test_slip_threshold_near_zero_stays_readable():
    t = np.linspace(0, 10, 2000)
    score = np.abs(np.sin(t * 3)) * 50
    truth = np.array([1.0, 2.0, 3.0])
    det = np.array([1.01, 2.5, 2.6])
    fig = slip_figure(t, score, truth, det, np.array([0]), np.array([1, 2]), 0.05, "torsion")
    events, ax = fig.axes
    assert ax.get_yscale() == "symlog"
    labels = fig.legends[0].get_texts()
    assert {"TP (1)", "FP (2)", "FN, missed (2)", "threshold 0.05"} <= {x.get_text() for x in labels}
    assert "F1 0.33" in events.get_title()
    plt.close(fig)
