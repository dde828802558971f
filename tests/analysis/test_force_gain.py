"""The CNN's R² gain over the linear baseline and its bootstrap interval over test trials."""

import json

import numpy as np

from analysis.metrics import r2_score
from analysis.sections.force import r2_gain_ci
from layerskin_exp.demo import force_summary


def _trials(n_trials=30, frames=40, seed=0):
    rng = np.random.default_rng(seed)
    trial = np.repeat(np.arange(n_trials), frames)
    y = rng.normal(size=(len(trial), 3)) + rng.normal(size=(n_trials, 3))[trial]  # trial-level spread
    return rng, trial, y


def test_a_clearly_better_model_has_an_interval_above_zero_and_the_swap_below():
    rng, trial, y = _trials()
    good = y + 0.2 * rng.normal(size=y.shape)
    poor = y + 1.0 * rng.normal(size=y.shape)
    g = r2_gain_ci(y, good, poor, trial)
    for ax, (gain, lo, hi) in g.items():
        i = "Fx Fy Fz".split().index(ax)
        assert gain == r2_score(y, good)[i] - r2_score(y, poor)[i]
        assert 0 < lo <= gain <= hi
    # Swapping the models must flip the verdict (the check can fail).
    assert all(hi < 0 for _, _, hi in r2_gain_ci(y, poor, good, trial).values())


def test_a_gain_carried_by_a_few_trials_is_not_resolved():
    rng, trial, y = _trials()
    base = y + 0.5 * rng.normal(size=y.shape)
    pred = base.copy()
    lucky = np.isin(trial, [0, 1])  # the model is better on two trials only
    pred[lucky] = y[lucky]
    gain, lo, hi = r2_gain_ci(y, pred, base, trial)["Fy"]
    assert gain > 0 and lo <= 0 < hi
    # Resampling frames instead of trials would call this resolved: trials are the unit here.
    assert r2_gain_ci(y, pred, base, np.arange(len(trial)))["Fy"][1] > 0


def test_the_demo_prints_the_gain_with_its_interval(tmp_path):
    r = {"study": {"force": {}}, "force_split": {"test_trials": 43},
         "force": {m: {ax: {"r2": v} for ax in ("Fx", "Fy", "Fz")} for m, v in (("linear", 0.5), ("T-s5", 0.7))},
         "force_gain_over_linear": {"confidence": 0.95, "T-s5": {"Fx": [0.2, -0.1, 0.5], "Fy": [0.2, 0.05, 0.3],
                                                                  "Fz": [0.2, 0.1, 0.3]}},
         "force_training": {}}
    (tmp_path / "results.json").write_text(json.dumps(r))
    text = force_summary(tmp_path / "results.json")
    assert "95 % CI over the 43 test trials" in text and "Fy +0.200 [+0.050, +0.300]" in text


def test_below_the_stated_minimum_of_test_trials_the_interval_is_undefined(tmp_path):
    from analysis import study
    from analysis.markdown import json_safe, write_markdown
    from analysis.sections.force import GAIN_MIN_TEST_TRIALS

    rng, trial, y = _trials(n_trials=GAIN_MIN_TEST_TRIALS - 1)
    base, pred = y + 0.5 * rng.normal(size=y.shape), y + 0.2 * rng.normal(size=y.shape)
    few = r2_gain_ci(y, pred, base, trial)
    for i, (gain, lo, hi) in enumerate(few.values()):
        assert gain == r2_score(y, pred)[i] - r2_score(y, base)[i]  # the gain itself is still given
        assert np.isnan(lo) and np.isnan(hi)
    more = np.repeat(np.arange(GAIN_MIN_TEST_TRIALS), 4)
    assert all(np.isfinite(v).all() for v in r2_gain_ci(y[:len(more)], pred[:len(more)], base[:len(more)],
                                                           more).values())
    # what the report and the demo print: the gain, the interval said undefined, the minimum stated
    r = json_safe({"study": study.ALL, "force_split": {"test_trials": GAIN_MIN_TEST_TRIALS - 1},
                   "force": {m: {ax: {"r2": 0.5, "mae": 0.1} for ax in few} for m in ("linear", "T-s5")},
                   "force_gain_over_linear": {"confidence": 0.95, "min_test_trials": GAIN_MIN_TEST_TRIALS,
                                              "T-s5": few},
                   "force_training": {}})
    write_markdown(tmp_path / "report.md", r, [])
    md = (tmp_path / "report.md").read_text()
    gx = few["Fx"][0]
    assert f"| Fx | {gx:+.3f} [interval undefined] |" in md
    assert f"below {GAIN_MIN_TEST_TRIALS} test trials the interval is undefined" in md
    (tmp_path / "results.json").write_text(json.dumps(r))
    text = force_summary(tmp_path / "results.json")
    assert f"Fx {gx:+.3f} [undefined]" in text and f"undefined below {GAIN_MIN_TEST_TRIALS}" in text
