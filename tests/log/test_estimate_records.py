"""Live estimates round-trip through the session log as two streams."""

import numpy as np

from layerskin_exp.log import SessionWriter, load_session
from layerskin_exp.types import SkinEstimate


def test_estimates_come_back_as_force_and_slip_streams(tmp_path):
    path = tmp_path / "s.mcap"
    with SessionWriter(path, metadata={"config": {}}, labels={}) as w:
        for k in range(4):
            score = None if k == 3 else 0.5 * k  # no detector for the last one: no slip message
            w.write(SkinEstimate(np.array([0.1, -0.2, 1.0 + k]), score, k == 2, k, 10**9 + k * 11_800_000,
                                 10**9 + k * 11_800_000 + 9_400_000))
        w.close("complete")
    s = load_session(path, warn=False)
    f, sl = s.streams["estimate_force"], s.streams["estimate_slip"]
    np.testing.assert_allclose(f["force_n"][:, 2], [1, 2, 3, 4])
    np.testing.assert_array_equal(f["seq"], [0, 1, 2, 3])
    np.testing.assert_allclose(sl["score"], [0.0, 0.5, 1.0])
    assert sl["slip"].tolist() == [False, False, True]
