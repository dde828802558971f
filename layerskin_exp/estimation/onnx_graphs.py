"""The estimator's force model as two torch graphs for ONNX export (layerskin_exp.estimation.export,
and the online estimator's onnxruntime backend): the frame encoder, and the heads on a window."""

from __future__ import annotations

import io
import warnings

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
