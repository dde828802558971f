"""Marker corners refined from the markers' straight outer sides.

The detector's corners (cornerSubPix, a gradient estimator on a blurred 90-degree corner) sit
~0.1-0.2 px inside the true ones and drift with the inner bit pattern inside their window: a
0.5 % scale error, i.e. ~0.7 mm of depth at 120 mm, and tilt errors of several degrees. Here each
outer side is located to a few thousandths of a pixel from intensity profiles across it, well
away from the corners, and the corners are the intersections of the four fitted lines.
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

# Edge profiles for the corner refinement (px). Across a side: +-PROFILE_HALF_PX about the
# detector's outline, inside the black border (1 module, ~6 px) and the quiet zone (~10 px);
# along it: PROFILES_PER_SIDE profiles, skipping CORNER_SKIP_PX at each end where the blurred
# corner rounds the edge.
PROFILE_HALF_PX = 3.0
PROFILE_STEP_PX = 0.25
PROFILES_PER_SIDE = 48
CORNER_SKIP_PX = 4.0
MIN_CONTRAST_GRAY = 40.0  # below this a side is not a clean black/white edge: keep the detector's corners
MAX_REFINE_SHIFT_PX = 1.5  # a refined corner further than this from the detector's is rejected

_R_PX = np.arange(-PROFILE_HALF_PX, PROFILE_HALF_PX + 1e-9, PROFILE_STEP_PX)  # (I,) offsets across a side
_U = np.linspace(0.0, 1.0, PROFILES_PER_SIDE)  # (J,) fractions of a side's usable length
_PLATEAU = max(1, int(round(0.75 / PROFILE_STEP_PX)))  # samples in the outer 0.75 px of each profile end
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _side_frames(c):
    """Per side of each (4, 2) quad in c (M, 4, 2): length (M, 4), unit direction and outward unit normal (M, 4, 2)."""
    m_count = c.shape[0]
    length = np.empty((m_count, 4))
    t = np.empty((m_count, 4, 2))
    n = np.empty((m_count, 4, 2))
    for m in range(m_count):
        mx = (c[m, 0, 0] + c[m, 1, 0] + c[m, 2, 0] + c[m, 3, 0]) / 4.0
        my = (c[m, 0, 1] + c[m, 1, 1] + c[m, 2, 1] + c[m, 3, 1]) / 4.0
        for k in range(4):
            k1 = (k + 1) % 4
            dx, dy = c[m, k1, 0] - c[m, k, 0], c[m, k1, 1] - c[m, k, 1]
            ln = math.sqrt(dx * dx + dy * dy)
            length[m, k] = ln
            t[m, k, 0], t[m, k, 1] = dx / ln, dy / ln
            # Outward: the normal points away from the quad's centre as seen from the side's midpoint.
            side = (c[m, k, 0] + dx / 2 - mx) * t[m, k, 1] - (c[m, k, 1] + dy / 2 - my) * t[m, k, 0]
            sg = 1.0 if side > 0 else (-1.0 if side < 0 else 0.0)
            n[m, k, 0], n[m, k, 1] = sg * t[m, k, 1], -sg * t[m, k, 0]
    return length, t, n


@_jit
def _profile_maps(c, r_px, u, skip_px):
    """Sample points of the edge profiles: x and y maps (M * 4 * J, I) float32; profile j of side k
    of marker m is row (m * 4 + k) * J + j, centred on the side at skip_px + u[j] (length - 2 skip_px)."""
    length, t, n = _side_frames(c)
    n_j, n_i = u.size, r_px.size
    map_x = np.empty((c.shape[0] * 4 * n_j, n_i), np.float32)
    map_y = np.empty_like(map_x)
    for m in range(c.shape[0]):
        for k in range(4):
            usable = max(length[m, k] - 2 * skip_px, 0.0)
            for j in range(n_j):
                s = skip_px + usable * u[j]
                px, py = c[m, k, 0] + s * t[m, k, 0], c[m, k, 1] + s * t[m, k, 1]
                row = (m * 4 + k) * n_j + j
                for i in range(n_i):
                    map_x[row, i] = px + r_px[i] * n[m, k, 0]
                    map_y[row, i] = py + r_px[i] * n[m, k, 1]
    return map_x, map_y


@_jit
def _fit_corners(c, prof, r_px, u, skip_px, step_px, plateau, min_contrast, max_shift_px):
    """Corners (M, 4, 2) from the profiles (M * 4 * J, I) sampled at _profile_maps' points.

    Per side: dark (inner) and bright (outer) levels from the profiles' end plateaus, each
    profile's edge offset from its coverage integral (trapezoid rule), a least-squares line
    offset = a + b s through those, and each corner where its two sides' lines meet. A marker
    with a short or low-contrast side, or a corner moved further than max_shift_px, keeps c."""
    length, t, n = _side_frames(c)
    m_count, n_j, n_i = c.shape[0], u.size, r_px.size
    half = (n_i - 1) * step_px / 2.0
    out = c.copy()
    p0 = np.empty((4, 2))
    dirs = np.empty((4, 2))
    s = np.empty(n_j)
    edge = np.empty(n_j)
    for m in range(m_count):
        ok = True
        for k in range(4):
            if length[m, k] < 2 * skip_px + 4.0:
                ok = False
            usable = max(length[m, k] - 2 * skip_px, 0.0)
            base = (m * 4 + k) * n_j
            dark = 0.0
            bright = 0.0
            for j in range(n_j):
                for i in range(plateau):
                    dark += prof[base + j, i]
                    bright += prof[base + j, n_i - 1 - i]
            dark /= n_j * plateau
            bright /= n_j * plateau
            contrast = bright - dark
            if not contrast >= min_contrast:
                ok = False
            for j in range(n_j):
                area = 0.0
                for i in range(n_i):
                    area += prof[base + j, i]
                area = (area - 0.5 * (prof[base + j, 0] + prof[base + j, n_i - 1])) * step_px
                s[j] = skip_px + usable * u[j]
                # Edge offset along n: the profile's width minus its area of coverage (0 dark .. 1 bright).
                edge[j] = half - (area - 2 * half * dark) / max(contrast, 1e-6)
            sm, em = s.mean(), edge.mean()
            sxx = 0.0
            sxy = 0.0
            for j in range(n_j):
                sxx += (s[j] - sm) ** 2
                sxy += (s[j] - sm) * (edge[j] - em)
            b = sxy / max(sxx, 1e-12)
            a = em - b * sm
            # The side is c + a n + s (t + b n).
            for ax in range(2):
                p0[k, ax] = c[m, k, ax] + a * n[m, k, ax]
                dirs[k, ax] = t[m, k, ax] + b * n[m, k, ax]
        if not ok:
            continue
        corners = np.empty((4, 2))
        for k in range(4):
            kp = (k + 3) % 4  # corner k is where side k - 1 meets side k
            det = dirs[kp, 0] * -dirs[k, 1] + dirs[k, 0] * dirs[kp, 1]
            if det == 0.0:
                ok = False
                break
            rx, ry = p0[k, 0] - p0[kp, 0], p0[k, 1] - p0[kp, 1]
            v = (rx * -dirs[k, 1] + dirs[k, 0] * ry) / det
            corners[k, 0] = p0[kp, 0] + v * dirs[kp, 0]
            corners[k, 1] = p0[kp, 1] + v * dirs[kp, 1]
            if not (abs(corners[k, 0] - c[m, k, 0]) <= max_shift_px and abs(corners[k, 1] - c[m, k, 1]) <= max_shift_px):
                ok = False
        if ok:
            out[m] = corners
    return out


def refine_marker_corners(img: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """(M, 4, 2) marker corners refined from the markers' straight outer sides.

    img: grey image (h, w); corners_px: (M, 4, 2) detector corners in img's pixel coordinates
    (pixel centres are integers), in order around each marker. Each side's edge is located by
    the coverage integral of intensity profiles across it (exact for a symmetric blur of a step,
    no threshold), a line is fitted through those edge points, and each corner is the
    intersection of its two sides. A marker whose edges are not clean keeps its input corners.
    The geometry runs in compiled kernels; the profiles are sampled by cv2.remap (bilinear).
    """
    c = np.ascontiguousarray(corners_px, np.float64).reshape(-1, 4, 2)
    if c.shape[0] == 0:
        return c.copy()
    map_x, map_y = _profile_maps(c, _R_PX, _U, CORNER_SKIP_PX)
    prof = cv2.remap(img.astype(np.float32), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return _fit_corners(c, prof, _R_PX, _U, CORNER_SKIP_PX, PROFILE_STEP_PX, _PLATEAU, MIN_CONTRAST_GRAY,
                        MAX_REFINE_SHIFT_PX)
