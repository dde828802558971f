"""A sensitivity screening result (`python -m protocols.sensitivity out=FILE`) read back for the
report: `load_result(path)` checks and reads it, `bands(result, study, ours)` sets each outcome's
band over the simulator's brackets beside the study's value and a campaign's.

The screen itself runs campaigns, so it is a study beside the protocols it drives
(protocols.sensitivity); the report reads only the file.
"""

from __future__ import annotations

import json
from pathlib import Path

from layerskin_exp.config import ConfigError

PRODUCE = "`python -m protocols.sensitivity out=FILE`"
HOW_TO = (f"{PRODUCE} screens the brackets of layerskin_exp/sim/brackets.yaml (minutes on 2 cores; `size=quick` "
          "for a first look); pass the file to the report as `sensitivity=FILE`")


def load_result(path) -> dict:
    """The screening result written to `path`. ConfigError naming the `sensitivity` key and the
    value when it is missing, unreadable or not a screening result."""

    def refuse(why: str):
        raise ConfigError(f"sensitivity={path}: {why}; write one with {PRODUCE}")

    try:
        result = json.loads(Path(path).read_text())
    except FileNotFoundError:
        refuse("no such file")
    except IsADirectoryError:
        refuse("is a folder, not a screening result file")
    except OSError as e:
        refuse(f"cannot read it ({e.strerror or e})")
    except (UnicodeDecodeError, ValueError) as e:
        refuse(f"not JSON ({str(e).splitlines()[0]})")
    if not (isinstance(result, dict) and isinstance(result.get("morris"), dict)
            and isinstance(result.get("problem"), dict) and isinstance(result.get("samples"), list)):
        refuse("not a sensitivity screening result (needs its 'morris', 'problem' and 'samples' entries)")
    return result


def bands(result: dict, study: dict, ours: dict, top_fraction: float = 0.5) -> dict:
    """Per outcome of the screen: the band over the brackets (min..max over the Morris samples),
    the parameters that move it most (mu* at least `top_fraction` of the largest, largest first),
    the study's value (study[key]: {"value", "source"}; value None where the study gives none) and
    this campaign's (ours[key]: {"value", "source"} or absent), and where the study's value lies
    against the band ("inside", "above", "below"; None where there is nothing to compare). Rows in
    the result's order, labelled with its own outcome labels. study[key]["approximate"]: the
    study states the value in words ("approximately")."""
    meta = result.get("outcomes") or {}
    rows = []
    for key, m in result["morris"].items():
        label, unit = meta.get(key, {}).get("label", key), meta.get(key, {}).get("unit", "")
        st, us = study.get(key) or {"value": None, "source": "not reported"}, ours.get(key) or {}
        row = {"outcome": key, "label": label, "unit": unit, "study": st.get("value"), "study_source": st.get("source"),
               "study_approximate": bool(st.get("approximate", False)),
               "ours": us.get("value"), "ours_source": us.get("source"), "band": None, "missing": m.get("missing", 0),
               "moved_most_by": [], "study_vs_band": None}
        if "mu_star" in m:
            lo, hi = (float(v) for v in m["range"])
            row["band"] = [lo, hi]
            mu = m["mu_star"]
            top = max(mu.values(), default=0.0)
            if top > 0:
                row["moved_most_by"] = [{"parameter": n, "mu_star": float(mu[n])}
                                        for n in sorted(mu, key=lambda n: -mu[n]) if mu[n] >= top_fraction * top]
            if row["study"] is not None:
                row["study_vs_band"] = "below" if row["study"] < lo else "above" if row["study"] > hi else "inside"
        else:
            row["reason"] = m.get("reason", "undefined")
        rows.append(row)
    return {"size": result.get("size"), "campaign": result.get("campaign"), "n_samples": len(result["samples"]),
            "trajectories": result.get("trajectories"), "brackets_file": result.get("brackets_file"),
            "parameters": list(result["problem"].get("names", [])), "rows": rows}
