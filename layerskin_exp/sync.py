"""Clock alignment: map each device's clock onto the host's monotonic timeline.

Every stream gives pairs (device_t, host_t) where host_t is the host receive time. The model is

    host_t = offset + (1 + drift) * device_t + delay,      delay >= 0,

with a one-sided transport delay (a message is never received before it is sent). A
least-squares line is biased by the mean delay and pulled around by its long tail; the
lower envelope is not: we take the line below every point that minimises the summed vertical
gap (host - line), the linear program of Duda/Moon-style one-way clock estimation. Its optimum
is the edge of the lower convex hull of the points that spans the mean device time, so we find
that edge with Qhull instead of running a general LP solver over every sample.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError


@dataclass(frozen=True)
class ClockMap:
    """host_t_ns ≈ offset_ns + (1 + drift) * device_t_ns (the zero-delay line).

    offset_ns: host time at device time 0 (ns). drift: dimensionless rate error (50 ppm = 5e-5).
    n_points: pairs used. delay_median_ns / delay_max_ns: host_t minus the line, i.e. the
    transport delay above the fastest observed one.
    """

    offset_ns: int
    drift: float
    n_points: int = 0
    delay_median_ns: float = 0.0
    delay_max_ns: float = 0.0

    def to_host(self, device_t_ns) -> np.ndarray:
        """Device times (N,) int64 ns -> host timeline (N,) int64 ns.

        Integer parts stay in int64 so epoch-sized device times keep ns resolution.
        """
        d = np.asarray(device_t_ns, dtype=np.int64)
        return d + np.int64(self.offset_ns) + np.rint(self.drift * d.astype(np.float64)).astype(np.int64)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ClockMap:
        return cls(
            offset_ns=int(d["offset_ns"]),
            drift=float(d["drift"]),
            n_points=int(d.get("n_points", 0)),
            delay_median_ns=float(d.get("delay_median_ns", 0.0)),
            delay_max_ns=float(d.get("delay_max_ns", 0.0)),
        )


def _lower_support_line(x: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """Line r = a + b*x below all points minimising sum(r - line): (a, b).

    x, r: (N,) float64, x not all equal. The objective is n*(mean(r) - a - b*mean(x)), so the
    optimum is the lower-hull edge whose x-range contains mean(x).
    """
    x_mean = float(x.mean())
    # Normalise so Qhull sees a well-conditioned point set (x spans ~1e12 ns, r ~1e6 ns).
    x_span = float(np.ptp(x))
    r_span = float(np.ptp(r))
    try:
        if r_span == 0.0:
            raise QhullError("all residuals equal")
        pts = np.column_stack(((x - x.min()) / x_span, (r - r.min()) / r_span))
        hull = ConvexHull(pts)
        verts = hull.vertices  # counter-clockwise in 2-D
    except QhullError:
        # Degenerate (collinear) points: the least-squares line is exact; lower it onto the points.
        b = float(np.polyfit(x, r, 1)[0]) if r_span else 0.0
        return float(np.min(r - b * x)), b
    # Counter-clockwise order walks the lower hull from the leftmost to the rightmost vertex.
    vx, vr = x[verts], r[verts]
    # Leftmost vertex, the lowest one if two share the same x.
    start = int(np.lexsort((vr, vx))[0])
    ring = np.roll(verts, -start)
    end = int(np.argmax(x[ring]))
    lower = ring[: end + 1]
    lx, lr = x[lower], r[lower]
    k = int(np.searchsorted(lx, x_mean, side="right")) - 1
    k = min(max(k, 0), len(lower) - 2)
    b = float((lr[k + 1] - lr[k]) / (lx[k + 1] - lx[k]))
    a = float(lr[k] - b * lx[k])
    # Guard against rounding in the hull: the line must stay below every point.
    a = min(a, float(np.min(r - b * x)))
    return a, b


def estimate_clock_map(device_t_ns, host_t_ns) -> ClockMap:
    """Estimate the zero-delay line host = offset + (1 + drift) * device from (N,) pairs.

    device_t_ns, host_t_ns: (N,) int ns. Needs N >= 1; with one pair, or a device clock that
    never advances, drift is 0 and the offset is the smallest host - device gap.
    """
    d = np.asarray(device_t_ns, dtype=np.int64)
    h = np.asarray(host_t_ns, dtype=np.int64)
    if d.shape != h.shape or d.ndim != 1 or d.size == 0:
        raise ValueError(
            f"estimate_clock_map needs two equal-length 1-D arrays with at least one pair; "
            f"got shapes {d.shape} and {h.shape}"
        )
    d0, h0 = int(d[0]), int(h[0])
    x = (d - d0).astype(np.float64)
    # Remove the unit slope first: the residual is offset + drift*device + delay, small numbers.
    r = ((h - h0) - (d - d0)).astype(np.float64)
    if d.size < 2 or np.ptp(x) == 0.0:
        a, b = float(r.min()), 0.0
    else:
        a, b = _lower_support_line(x, r)
    delay = r - (a + b * x)
    # host = h0 + a + (1+b)(d - d0)  =>  offset = h0 - d0 + a - b*d0
    offset_ns = (h0 - d0) + int(round(a - b * d0))
    return ClockMap(
        offset_ns=offset_ns,
        drift=b,
        n_points=int(d.size),
        delay_median_ns=float(np.median(delay)),
        delay_max_ns=float(delay.max()),
    )


__all__ = ["ClockMap", "estimate_clock_map"]
