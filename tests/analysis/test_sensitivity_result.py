"""Reading a screening result back for the report: the refusal of a bad file, and each outcome's
band beside the study, on a synthetic result (no screen runs here)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from analysis import sensitivity_result as sr
from analysis import study
from protocols import sensitivity as sens

sys.path.insert(0, str(Path(__file__).parent))
from synthetic import write_sensitivity_result  # noqa: E402


def _synthetic(tmp_path):
    return write_sensitivity_result(tmp_path / "sens.json")


def test_bands_place_the_study_against_each_band(tmp_path):
    res = sr.load_result(_synthetic(tmp_path))
    ours = {"cop_shift_at_2n_mm": {"value": 1.25, "source": "this section"}}
    rows = {r["outcome"]: r for r in sr.bands(res, study.SENSITIVITY_OUTCOMES, ours)["rows"]}
    assert list(rows) == [k for k in sens.OUTCOMES if k in res["morris"]]  # the screen's order
    cop = rows["cop_shift_at_2n_mm"]
    assert cop["band"] == [1.0, 1.5] and cop["study"] == 2.20 and cop["study_vs_band"] == "above"
    assert cop["ours"] == 1.25 and "Sec. IV-A" in cop["study_source"]
    # moved most: mu* at least half the largest, largest first; the 0.01 parameter is not named
    assert [m["parameter"] for m in cop["moved_most_by"]] == ["sim.sheet.interface", "sim.cover.friction"]
    assert rows["position_cv"]["study_vs_band"] == "inside"
    assert rows["grip_preload_n"]["study_vs_band"] == "below" and rows["grip_preload_n"]["missing"] == 2
    # the study gives no shift per newton: nothing is compared, nothing invented
    assert rows["shift_per_n_mm"]["study"] is None and rows["shift_per_n_mm"]["study_vs_band"] is None
    assert rows["linear_r2_shear"]["band"] is None and rows["linear_r2_shear"]["study_vs_band"] is None
    # the comparison follows the band: move the band over the study's value and it reads inside
    res["morris"]["cop_shift_at_2n_mm"]["range"] = [2.0, 2.5]
    rows = {r["outcome"]: r for r in sr.bands(res, study.SENSITIVITY_OUTCOMES, ours)["rows"]}
    assert rows["cop_shift_at_2n_mm"]["study_vs_band"] == "inside"


def test_a_bad_screening_result_is_refused_naming_the_key_and_value(tmp_path):
    from layerskin_exp.config import ConfigError

    (tmp_path / "notjson.json").write_text("{ not json")
    (tmp_path / "results.json").write_text(json.dumps({"force": {}}))  # a report's results, not a screen
    for bad, why in ((tmp_path / "nope.json", "no such file"), (tmp_path, "folder"),
                     (tmp_path / "notjson.json", "not JSON"), (tmp_path / "results.json", "not a sensitivity")):
        with pytest.raises(ConfigError, match=why) as e:
            sr.load_result(bad)
        assert str(e.value).startswith(f"sensitivity={bad}: ") and "\n" not in str(e.value)
