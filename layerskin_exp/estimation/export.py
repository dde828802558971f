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
import io
import json
import sys
import warnings
from pathlib import Path

import torch
from torch import nn

from layerskin_exp.estimation.artifact import Estimator
from layerskin_exp.rig import SKIN_SHAPE


class EncoderGraph(nn.Module):
    """Scaled maps (N, 2, 16, 16) -> encodings (N, 64): channels, normalisation, frame encoder."""

    def __init__(self, est: Estimator) -> None:
        super().__init__()
        m = est.force_model
        self.layers = m.layers
        self.encoder = m.model_.encoder
        self.register_buffer("x_mean", torch.as_tensor(m.norm_["x_mean"]).reshape(1, -1, 1, 1))
        self.register_buffer("x_std", torch.as_tensor(m.norm_["x_std"]).reshape(1, -1, 1, 1))

    def forward(self, maps: torch.Tensor) -> torch.Tensor:
        if self.layers == "T":
            x = torch.cat([maps, maps[:, :1] - maps[:, 1:2]], dim=1)
        elif self.layers == "S":
            x = maps[:, :1]
        else:
            x = maps[:, 1:2]
        return self.encoder((x - self.x_mean) / self.x_std)


class HeadsGraph(nn.Module):
    """Window of encodings (B, T, 64) -> force (B, 3) in N."""

    def __init__(self, est: Estimator) -> None:
        super().__init__()
        m = est.force_model
        self.model = m.model_
        self.register_buffer("y_mean", torch.as_tensor(m.norm_["y_mean"])[None])
        self.register_buffer("y_std", torch.as_tensor(m.norm_["y_std"])[None])

    def forward(self, window: torch.Tensor) -> torch.Tensor:
        return self.model.heads(window) * self.y_std + self.y_mean


def _export(module: nn.Module, example: torch.Tensor, f, names: tuple[str, str], opset: int) -> None:
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(module.eval(), (example,), f, input_names=[names[0]], output_names=[names[1]],
                          dynamic_axes={names[0]: {0: "n"}, names[1]: {0: "n"}}, opset_version=opset,
                          dynamo=False)


def onnx_bytes(enc: EncoderGraph, heads: HeadsGraph, seq_len: int, opset: int = 17) -> tuple[bytes, bytes]:
    """The two graphs as serialized ONNX models, in memory."""
    out = []
    for module, example, names in ((enc, torch.zeros(1, 2, *SKIN_SHAPE), ("maps", "encoding")),
                                   (heads, torch.zeros(1, seq_len, 64), ("window", "force_n"))):
        buf = io.BytesIO()
        _export(module, example, buf, names, opset)
        out.append(buf.getvalue())
    return out[0], out[1]


def export_onnx(artifact, out_dir=None, opset: int = 17) -> dict[str, Path]:
    """Write the two graphs and the JSON sidecar; returns their paths."""
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
