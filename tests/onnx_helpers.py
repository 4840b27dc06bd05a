"""Tiny torch networks for the ONNX tests (no training): a colour classifier that segments label-coloured
scenes as the palette says, and wrappers that change its input/output contract without changing its answer."""

from __future__ import annotations

import io
import warnings

import numpy as np
import onnx
import torch
from torch import nn

from el.classes.labels import PALETTE

SHARPNESS = 40.0


class ColourNet(nn.Module):
    """logit_c = k (2 x.c - |c|^2) after a 3x3 mean: the nearest palette colour wins (colours in [0, 1])."""

    def __init__(self) -> None:
        super().__init__()
        self.blur = nn.Conv2d(3, 3, 3, padding=1, padding_mode="replicate", groups=3, bias=False)
        self.head = nn.Conv2d(3, len(PALETTE), 1)
        c = torch.tensor(PALETTE, dtype=torch.float32) / 255.0
        with torch.no_grad():
            self.blur.weight.fill_(1.0 / 9.0)
            self.head.weight.copy_((2 * SHARPNESS * c)[:, :, None, None])
            self.head.bias.copy_(-SHARPNESS * (c * c).sum(1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.blur(x))


class Variant(nn.Module):
    """ColourNet behind another contract: bgr input, nhwc layout, mean/std on 0-255, probabilities out,
    permuted output channels, or a wrong class count / NaN output (to be refused)."""

    def __init__(self, net: nn.Module, *, bgr: bool = False, nhwc: bool = False, mean_std: bool = False,
                 probabilities: bool = False, order: list[int] | None = None, drop: bool = False,
                 nan: bool = False) -> None:
        super().__init__()
        self.net, self.bgr, self.nhwc, self.mean_std = net, bgr, nhwc, mean_std
        self.probabilities, self.order, self.drop, self.nan = probabilities, order, drop, nan

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.nhwc:
            x = x.permute(0, 3, 1, 2)
        if self.mean_std:  # the input is (v - MEAN) / STD on 0-255 values: back to [0, 1]
            x = (x * torch.tensor(STD).view(1, 3, 1, 1) + torch.tensor(MEAN).view(1, 3, 1, 1)) / 255.0
        if self.bgr:
            x = x.flip(1)
        y = self.net(x)
        if self.probabilities:
            y = torch.softmax(y, dim=1)
        if self.order is not None:
            y = y[:, self.order]
        if self.drop:
            y = y[:, :-1]
        if self.nan:
            y = y * float("nan")
        if self.nhwc:
            y = y.permute(0, 2, 3, 1)
        return y


MEAN = [120.0, 110.0, 100.0]
STD = [60.0, 50.0, 70.0]


def export_raw(module: nn.Module, path, *, nhwc: bool = False, static: tuple[int, int] | None = None,
               meta: dict[str, str] | None = None) -> None:
    """torch.onnx.export of a module, dynamic H and W unless ``static`` (H, W); optional metadata_props."""
    h, w = static or (24, 40)
    example = torch.rand(1, h, w, 3) if nhwc else torch.rand(1, 3, h, w)
    axes = None if static else ({"x": {1: "h", 2: "w"}} if nhwc else {"x": {2: "h", 3: "w"}})
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the legacy exporter's deprecation and tracer notes
        torch.onnx.export(module.eval(), (example,), buf, input_names=["x"], output_names=["y"], dynamic_axes=axes,
                          opset_version=17, dynamo=False)
    proto = onnx.load_from_string(buf.getvalue())
    for k, v in (meta or {}).items():
        e = proto.metadata_props.add()
        e.key, e.value = k, v
    with open(path, "wb") as f:
        f.write(proto.SerializeToString())


def noisy_colours(ids: np.ndarray, seed: int = 0) -> np.ndarray:
    """A label-coloured frame with a little noise (uint8)."""
    from el.classes.labels import ids_to_colors

    rng = np.random.default_rng(seed)
    img = ids_to_colors(ids).astype(np.int16) + rng.integers(-12, 12, (*ids.shape, 3))
    return np.clip(img, 0, 255).astype(np.uint8)
