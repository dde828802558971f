"""Per-frame features of one skin layer: total pressure, centre of pressure, principal-axis angle.

Every function takes pressure maps of shape (..., 16, 16) — any leading batch shape, [row, column],
row i along y and column j along x — and works on whole sessions at once (no per-frame loop).
Coordinates come from the skin geometry (`SkinConfig.taxel_centres_mm()`, origin at the array
centre), so CoPs are in mm.

Negative pressures (noise after baseline subtraction) are expected to be clipped by the caller;
these functions use the maps as given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from layerskin_exp.config import SkinConfig

DEFAULT_EPS = 1e-3  # avoids 0/0 on an unloaded map; small against a loaded total


def _axes(skin: SkinConfig | None) -> tuple[np.ndarray, np.ndarray]:
    """(x_mm (n,), y_mm (n,)): column and row centre coordinates."""
    c = (skin or SkinConfig()).taxel_centres_mm()
    return c, c


def total_pressure(maps: np.ndarray) -> np.ndarray:
    """p = Σ p_ij. maps (..., 16, 16) -> (...)."""
    return maps.sum(axis=(-2, -1))


@dataclass(frozen=True)
class Moments:
    """Raw pressure moments of maps (..., 16, 16): each field has shape (...)."""

    total: np.ndarray  # Σ p
    sx: np.ndarray  # Σ p x
    sy: np.ndarray  # Σ p y
    sxx: np.ndarray  # Σ p x²
    syy: np.ndarray  # Σ p y²
    sxy: np.ndarray  # Σ p x y


def moment_basis(skin: SkinConfig | None = None, dtype=np.float64) -> np.ndarray:
    """(n*n, 6) per-taxel weights [1, x, y, x², y², xy] in map order (row-major, row = y)."""
    x, y = _axes(skin)
    yy, xx = np.meshgrid(y, x, indexing="ij")
    xx, yy = xx.ravel(), yy.ravel()
    return np.stack([np.ones_like(xx), xx, yy, xx * xx, yy * yy, xx * yy], axis=1).astype(dtype)


def moments(maps: np.ndarray, skin: SkinConfig | None = None) -> Moments:
    """Zeroth, first and second pressure moments, all six from one matrix product."""
    dt = maps.dtype if maps.dtype.kind == "f" else np.float64
    n = maps.shape[-1]
    flat = maps.reshape(-1, maps.shape[-2] * n)
    if flat.dtype != dt:
        flat = flat.astype(dt)
    m = flat @ moment_basis(skin, dt)  # (F, 6)
    lead = maps.shape[:-2]
    f = [m[:, i].reshape(lead) for i in range(6)]
    return Moments(total=f[0], sx=f[1], sy=f[2], sxx=f[3], syy=f[4], sxy=f[5])


def cop_and_angle(m: Moments, eps: float = DEFAULT_EPS) -> tuple[np.ndarray, np.ndarray]:
    """The one definition of the CoP and the PCA angle, from raw moments (fields of shape (...)).

    c = Σ p_ij (x_j, y_i) / (ε + p) -> (..., 2) mm; θ = ½ atan2(2 C_xy, C_xx − C_yy) -> (...) rad,
    from the pressure-weighted coordinate covariances, θ in (−π/2, π/2] from +x towards +y.
    """
    d = eps + m.total
    cx, cy = m.sx / d, m.sy / d
    cxx = m.sxx / d - cx * cx
    cyy = m.syy / d - cy * cy
    cxy = m.sxy / d - cx * cy
    return np.stack([cx, cy], axis=-1), 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)


def centre_of_pressure(maps: np.ndarray, skin: SkinConfig | None = None,
                       eps: float = DEFAULT_EPS) -> np.ndarray:
    """c = Σ p_ij (x_j, y_i) / (ε + p). maps (..., 16, 16) -> (..., 2) in mm (x, y)."""
    return cop_and_angle(moments(maps, skin), eps)[0]


def pca_angle(maps: np.ndarray, skin: SkinConfig | None = None, eps: float = DEFAULT_EPS) -> np.ndarray:
    """θ = ½ atan2(2 C_xy, C_xx − C_yy) in rad, from pressure-weighted coordinate covariances.

    maps (..., 16, 16) -> (...), θ in (−π/2, π/2], measured from +x towards +y.
    """
    return cop_and_angle(moments(maps, skin), eps)[1]


def layer_features(maps: np.ndarray, skin: SkinConfig | None = None,
                   eps: float = DEFAULT_EPS) -> dict[str, np.ndarray]:
    """All features of one layer from one pass over the maps.

    Returns {"total": (...), "cop_mm": (..., 2), "angle_rad": (...)}.
    """
    m = moments(maps, skin)
    cop, angle = cop_and_angle(m, eps)
    return {"total": m.total, "cop_mm": cop, "angle_rad": angle}


def two_layer_features(maps: np.ndarray, skin: SkinConfig | None = None,
                       eps: float = DEFAULT_EPS) -> dict[str, np.ndarray]:
    """Features of both layers of preprocessed maps (K, 2, 16, 16), [superficial, deep].

    Returns per-layer totals p_s, p_d (K,), CoPs cop_s, cop_d (K, 2) mm, angles angle_s, angle_d
    (K,) rad, and the inter-layer shift dc = cop_s − cop_d (K, 2) mm.
    """
    m = moments(maps, skin)  # fields (K, 2)
    cop, ang = cop_and_angle(m, eps)  # (K, 2 layers, 2), (K, 2 layers)
    return {"p_s": m.total[:, 0], "p_d": m.total[:, 1], "cop_s": cop[:, 0], "cop_d": cop[:, 1],
            "angle_s": ang[:, 0], "angle_d": ang[:, 1], "dc": cop[:, 0] - cop[:, 1]}


def interlayer_shift(superficial: np.ndarray, deep: np.ndarray, skin: SkinConfig | None = None,
                     eps: float = DEFAULT_EPS) -> np.ndarray:
    """Δc = c_superficial − c_deep. Both (..., 16, 16) -> (..., 2) mm."""
    return centre_of_pressure(superficial, skin, eps) - centre_of_pressure(deep, skin, eps)
