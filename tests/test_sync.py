"""Clock alignment against an injected truth, one-sided delays, and an independent LP."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from layerskin_exp.sync import ClockMap, estimate_clock_map

OFFSET_NS = 7_345_678_901
DRIFT = 50e-6


def _pairs(n, rng, delay):
    device = 2_000_000_000 + np.cumsum(rng.integers(2_000_000, 2_700_000, n)).astype(np.int64)
    truth = OFFSET_NS + device + np.rint(DRIFT * device).astype(np.int64)
    return device, truth, truth + np.rint(delay).astype(np.int64)


@pytest.mark.parametrize("kind", ["exponential", "gamma"])
def test_recovers_offset_and_drift_better_than_least_squares(kind):
    rng = np.random.default_rng(42)
    n = 20_000  # ~47 s at 424 Hz
    delay = rng.exponential(300_000, n) if kind == "exponential" else rng.gamma(2.0, 200_000, n)
    device, truth, host = _pairs(n, rng, 50_000 + delay)  # 50 us fixed latency + jitter
    m = estimate_clock_map(device, host)
    err = np.abs(m.to_host(device) - truth - 50_000)
    assert err.max() < 20_000  # 20 us, against jitter of several hundred us
    assert abs(m.drift - DRIFT) < 1e-6
    # Naive least squares on the same pairs: biased by the mean delay.
    b, a = np.polyfit((device - device[0]).astype(float), (host - device).astype(float), 1)
    ls = device + np.rint(a + b * (device - device[0])).astype(np.int64)
    ls_err = np.abs(ls - truth - 50_000)
    assert err.max() * 5 < ls_err.max()
    assert err.mean() * 5 < ls_err.mean()
    # Every pair lies on or above the estimated zero-delay line.
    assert np.all(host - m.to_host(device) >= -1)


def test_matches_the_linear_program():
    """Lower hull edge == LP: minimise sum(host - line) subject to host >= line."""
    rng = np.random.default_rng(3)
    device, truth, host = _pairs(400, rng, rng.gamma(1.5, 400_000, 400))
    m = estimate_clock_map(device, host)
    x = (device - device[0]).astype(float) / 1e9  # seconds, for a well-scaled LP
    r = (host - device - (host[0] - device[0])).astype(float) / 1e3  # us
    res = linprog(
        c=[-len(x), -x.sum()],
        A_ub=np.column_stack([np.ones_like(x), x]),
        b_ub=r,
        bounds=[(None, None), (None, None)],
        method="highs",
    )
    assert res.success
    a_us, b_us_per_s = res.x
    assert m.drift == pytest.approx(b_us_per_s * 1e3 / 1e9, abs=1e-9)
    lp_line = host[0] - device[0] + device + np.rint(a_us * 1e3 + b_us_per_s * x * 1e3).astype(np.int64)
    assert np.max(np.abs(m.to_host(device) - lp_line)) <= 2


def test_degenerate_inputs():
    d = np.array([10, 20, 30], dtype=np.int64)
    m = estimate_clock_map(d, d + 100)  # no jitter at all: collinear points
    assert m.offset_ns == 100 and m.drift == 0.0
    one = estimate_clock_map([5], [105])
    assert one.offset_ns == 100 and one.drift == 0.0
    frozen = estimate_clock_map([0, 0, 0], [7, 9, 8])  # device clock that never advances
    assert frozen.offset_ns == 7 and frozen.drift == 0.0
    with pytest.raises(ValueError, match="equal-length"):
        estimate_clock_map([1, 2], [1])


def test_epoch_sized_device_times_keep_ns_resolution():
    device = np.array([1_700_000_000_000_000_000 + k * 1_000_000 for k in range(100)], dtype=np.int64)
    host = device - 1_699_999_000_000_000_000
    m = estimate_clock_map(device, host)
    np.testing.assert_array_equal(m.to_host(device), host)
    assert ClockMap.from_dict(m.to_dict()) == m
