"""`python -m layerskin_exp.estimation.export ARTIFACT --format onnx [--out DIR]`

Writes, beside the artifact (or in DIR), for an artifact `T-s5.pt`:
    T-s5.encoder.onnx  maps (N, 2, 16, 16) float32 scaled maps [superficial, deep] -> encoding (N, 64);
                       input channels and their normalisation are inside the graph
    T-s5.heads.onnx    window (B, T, 64) encodings of T consecutive downsampled frames, oldest first
                       -> force_n (B, 3) Fx, Fy, Fz in N (each GRU head starts from a zero state)
    T-s5.onnx.json     the preprocessing from raw counts to scaled maps (the artifact's
                       `preprocess`, including the per-layer scale), the window length, the slip
                       detector and its cue, and the graphs' input/output names
A deployment encodes each downsampled frame once and keeps the last T encodings.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# torch and the artifact load when an artifact is exported, not for --help (benchmarks/cli_help);
# the graphs live in layerskin_exp.estimation.onnx_graphs (their names are still found here).
_GRAPHS = ("EncoderGraph", "HeadsGraph", "onnx_bytes")


def __getattr__(name: str):
    if name not in _GRAPHS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from layerskin_exp.estimation import onnx_graphs

    return getattr(onnx_graphs, name)


def export_onnx(artifact, out_dir=None, opset: int = 17) -> dict[str, Path]:
    """Write the two graphs and the JSON sidecar; returns their paths."""
    from layerskin_exp.estimation.artifact import Estimator
    from layerskin_exp.estimation.onnx_graphs import EncoderGraph, HeadsGraph, onnx_bytes

    artifact = Path(artifact)
    est = Estimator.load(artifact, device="cpu")
    out_dir = Path(out_dir) if out_dir is not None else artifact.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = artifact.stem
    paths = {"encoder": out_dir / f"{stem}.encoder.onnx", "heads": out_dir / f"{stem}.heads.onnx",
             "sidecar": out_dir / f"{stem}.onnx.json"}
    seq_len = est.force_model.seq_len
    enc, heads = onnx_bytes(EncoderGraph(est), HeadsGraph(est), seq_len, opset)
    paths["encoder"].write_bytes(enc)
    paths["heads"].write_bytes(heads)
    d = est.to_dict()
    sidecar = {"format": "layerskin-estimator-onnx", "artifact": artifact.name,
               "configuration": est.force_model.configuration, "seq_len": seq_len,
               "preprocess": d["preprocess"], "slip": d["slip"],
               "encoder": {"file": paths["encoder"].name, "input": "maps", "input_shape": ["n", 2, 16, 16],
                           "output": "encoding", "output_shape": ["n", 64]},
               "heads": {"file": paths["heads"].name, "input": "window", "input_shape": ["b", seq_len, 64],
                         "output": "force_n", "output_shape": ["b", 3], "units": "N",
                         "window": "the last seq_len encodings, oldest first; at a trial start the first "
                                   "frame's encoding repeated"}}
    paths["sidecar"].write_text(json.dumps(sidecar, indent=1))
    return paths


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m layerskin_exp.estimation.export", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("artifact", help="an estimator artifact written by the report (out/models/T-s5.pt)")
    p.add_argument("--format", choices=["onnx"], default="onnx")
    p.add_argument("--out", help="folder for the exported files (default: beside the artifact)")
    args = p.parse_args(argv)
    try:
        paths = export_onnx(args.artifact, args.out)
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
