"""The study's own figures (Cong et al., layered e-skin), printed beside ours in the report."""

FORCE = {  # model -> axis -> {r2, mae (N)}
    name: {ax: {"r2": r2, "mae": m} for ax, r2, m in zip(("Fx", "Fy", "Fz"), r2s, maes, strict=True)}
    for name, r2s, maes in (
        ("linear", (0.474, 0.443, 0.902), (0.275, 0.229, 0.318)),
        ("T-s1", (0.888, 0.937, 0.988), (0.098, 0.068, 0.105)),
        ("T-s5", (0.914, 0.944, 0.983), (0.094, 0.065, 0.113)),
        ("S-s1", (0.842, 0.900, 0.992), (0.126, 0.085, 0.094)),
        ("S-s5", (0.869, 0.894, 0.989), (0.118, 0.087, 0.104)),
        ("D-s1", (0.426, 0.457, 0.928), (0.217, 0.175, 0.252)),
        ("D-s5", (0.342, 0.396, 0.926), (0.231, 0.178, 0.256)),
    )
}

SLIP = {  # motion -> cue -> setting -> trial-macro F1
    "translation": {
        "interlayer": {"global": 0.672, "grip": 0.840, "oracle": 0.859},
        "superficial": {"global": 0.642, "grip": 0.795, "oracle": 0.836},
        "geometric": {"global": 0.652, "grip": 0.821, "oracle": 0.851},
        "f_xyz": {"global": 0.649, "grip": 0.808, "oracle": 0.855},
        "f_z": {"global": 0.638, "grip": 0.728, "oracle": 0.765},
    },
    "torsion": {
        "interlayer": {"global": 0.731, "grip": 0.787, "oracle": 0.809},
        "superficial": {"global": 0.621, "grip": 0.681, "oracle": 0.730},
        "geometric": {"global": 0.585, "grip": 0.651, "oracle": 0.675},
        "f_xyz": {"global": 0.607, "grip": 0.664, "oracle": 0.682},
        "f_z": {"global": 0.625, "grip": 0.695, "oracle": 0.720},
    },
}


def _track(a, r2, m):
    return {f"{g:g}": {"a": ai, "r2": ri, "mae": mi} for g, ai, ri, mi in zip((6, 9, 12, 15), a, r2, m, strict=True)}


TRACKING = {  # motion -> layer -> grip depth (mm) -> {a, r2, mae (mm or °)}
    "translation": {
        "deep": _track((1.35, 1.23, 1.22, 1.25), (0.996, 0.996, 0.989, 0.973), (0.13, 0.15, 0.26, 0.41)),
        "superficial": _track((0.94, 0.90, 0.91, 0.97), (0.991, 0.991, 0.973, 0.882), (0.19, 0.16, 0.25, 0.41)),
    },
    "torsion": {
        "deep": _track((1.16,) * 4, (0.897, 0.952, 0.973, 0.980), (3.92, 2.87, 2.10, 1.73)),
        "superficial": _track((0.92, 0.87, 0.84, 0.79), (0.953, 0.946, 0.975, 0.980), (2.46, 2.79, 1.90, 1.51)),
    },
}

CHARACTERIZATION = {
    "uniformity": {"cv": 0.145, "ci_low": 0.125, "ci_high": 0.162, "n_positions": 100, "matched_load_n": 2.0},
    "repeatability": {"median_cv": 0.062, "n_positions": 88},
    "cop_shift": {"median_mm": 2.20, "p10_mm": 1.41, "p90_mm": 2.97},
}

HEIGHTS = {
    "overall": {"h_x_mm": 3.64, "h_y_mm": 4.71},
    "lowest_bin": {"fz_n": [0.5, 1.0], "h_x_mm": 1.62, "h_y_mm": 1.44, "r2_x": 0.159, "r2_y": 0.125},
    "highest_bin": {"fz_n": [5.0, 6.5], "h_x_mm": 4.84, "h_y_mm": 6.53, "r2_x": 0.626, "r2_y": 0.725},
}

# The study's calibration campaign: shear within about ±2 N on each axis, normal load up to about 6.2 N.
FORCE_RANGE_N = {"Fx": {"min_n": -2.0, "max_n": 2.0}, "Fy": {"min_n": -2.0, "max_n": 2.0}, "abs_Fz_max_n": 6.2}

PRELOAD_N = {"6": 1.85, "9": 2.82, "12": 3.74, "15": 4.38}  # T-s5 estimate of the grip preload
SLIP_LATENCY_MS = {"before": 82, "after": 10}  # median tactile lead over vision

ALL = {"force": FORCE, "slip": SLIP, "tracking": TRACKING, "characterization": CHARACTERIZATION,
       "heights": HEIGHTS, "force_range_n": FORCE_RANGE_N, "preload_n": PRELOAD_N, "slip_latency_ms": SLIP_LATENCY_MS}

# The study's figure for each outcome of the sensitivity screen (protocols.sensitivity.OUTCOMES), with
# where it stands; None where the study gives none (its note says what it gives instead).
SENSITIVITY_OUTCOMES = {
    "shift_per_n_mm": {"value": None, "source": "not reported; only the shift at 1.9–2.1 N shear, Sec. IV-A"},
    "cop_shift_at_2n_mm": {"value": CHARACTERIZATION["cop_shift"]["median_mm"],
                           "source": "Sec. IV-A, trial-wise median at 1.9–2.1 N; 10th–90th percentile "
                                     f"{CHARACTERIZATION['cop_shift']['p10_mm']}–{CHARACTERIZATION['cop_shift']['p90_mm']}"},
    "linear_r2_shear": {"value": (FORCE["linear"]["Fx"]["r2"] + FORCE["linear"]["Fy"]["r2"]) / 2,
                        "source": f"Table II, linear: mean of Fx {FORCE['linear']['Fx']['r2']} and "
                                  f"Fy {FORCE['linear']['Fy']['r2']}, 70/15/15 trial split"},
    "superficial_r2_shear": {"value": None,
                             "source": "not reported for a linear probe; Table II's superficial-only CNN (S-s5) "
                                       f"gives {FORCE['S-s5']['Fx']['r2']} / {FORCE['S-s5']['Fy']['r2']}, "
                                       "a different estimator"},
    "position_cv": {"value": CHARACTERIZATION["uniformity"]["cv"],
                    "source": f"Sec. IV-A, 100 positions; 95 % CI {CHARACTERIZATION['uniformity']['ci_low']}–"
                              f"{CHARACTERIZATION['uniformity']['ci_high']}"},
    "slides_shear_reached": {"value": None, "source": "not reported"},
    "slide_fz_at_shear_n": {"value": 6.0, "approximate": True, "source": "Sec. V, in words: \"±2 N shear force at approximately "
                                                    "6 N normal load\""},
    "slide_max_shear_n": {"value": None, "source": "not reported; the slides stop at a 2 N target, recorded "
                                                   "Fx within ±2.01 N, Sec. III-A"},
    "grip_preload_n": {"value": PRELOAD_N["12"], "source": "Sec. III-B, g = 12 mm, estimated with the T-s5 "
                                                           "model, no F/T sensor in the gripper"},
}
