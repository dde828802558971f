"""The report's stream-health section: the drivers' counters summed per device over the sessions
used, and how many sessions lack them (written before they were stored)."""

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from analysis.markdown import _stream_health
from analysis.sections.streams import stream_health
from analysis.sessions import load_campaign

sys.path.insert(0, str(Path(__file__).parent))
from synthetic import calibration_trial  # noqa: E402


def _health(lost, corrupt=0):
    return {"skin": {"received": 500, "lost": lost, "duplicate": 0, "out_of_order": 0, "corrupt": corrupt,
                     "reconnects": 0, "dropped": 0},
            "ft": {"received": 250, "lost": 1, "duplicate": 2, "out_of_order": 0, "corrupt": 0, "reconnects": 0}}


def test_counters_are_summed_per_device_and_unrecorded_sessions_counted(tmp_path):
    rng = np.random.default_rng(0)
    for i, health in enumerate((_health(3, corrupt=1), _health(0), None)):
        calibration_trial(tmp_path / f"pos{i:03d}_press0.mcap", i, "press", 0, rng, n=120, stream_health=health)
    run = SimpleNamespace(camp=load_campaign(tmp_path, progress=False, workers=1), results={})
    stream_health(run)
    h = run.results["stream_health"]
    assert h["sessions"] == 3 and h["not_recorded"] == 1 and h["sessions_with_lost_skin_frames"] == 1
    assert h["devices"]["skin"] == {"received": 1000, "lost": 3, "duplicate": 0, "out_of_order": 0, "corrupt": 1,
                                    "reconnects": 0, "dropped": 0}
    assert h["devices"]["ft"]["duplicate"] == 4
    md = "\n".join(_stream_health(run.results))
    assert "## Stream health" in md and "3 sessions used" in md and "1 without the counters" in md
    assert "| skin | 1000 | 3 | 0 | 0 | 0 | 1 | 0 |" in md and "| ft | 500 | 2 | – | 4 | 0 | 0 | 0 |" in md
