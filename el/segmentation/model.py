"""The shipped segmentation network: a compact multi-scale dilated CNN with channel dropout.

In the spirit of MSDnet (the paper's model), :class:`MSDLite`:

- stem: two stride-2 3x3 convolutions (1/4 resolution: the skip features), a third to 1/8;
- context: residual blocks with dilations 1, 2, 4, 8 at 1/8 resolution (receptive field ~ 300 px);
- **dropout 1** (channel dropout on the 1/8 context features);
- multi-scale block: parallel 3x3 branches with dilations 1, 3, 6, 12, fused by a 1x1 convolution;
- **dropout 2**;
- decoder (FPN style): 1x1 + 3x3 convolutions of the context, upsampled x2 and added to a 3x3
  lateral convolution of the 1/4 skip features, BatchNorm + ReLU, 1x1 classifier, bilinear x4.

About 0.83 M parameters (3.3 MB of float32 weights); ~0.2 s for a 1024x576 frame on 2 CPU cores.

Contract (shared by every model the toolkit accepts, docs/architecture.md section 3.2): ``forward(x)`` maps RGB
float images ``x`` of shape (B, 3, H, W), values in [0, 1], to logits of shape (B, 8, H, W) for any
H, W >= 1 (the network pads internally, by edge replication, to a multiple of 8 and crops back).
The mean/std normalisation (ImageNet statistics) happens inside the model.

For Monte-Carlo dropout the forward pass is split in two:

- ``trunk(x) -> Features``: the deterministic part, everything before the first dropout layer
  (including the lateral convolution of the skip features, which no dropout reaches);
- ``head(features, mc=None) -> logits``: the stochastic rest. Both dropout layers sit before the
  multi-scale block and the decoder, i.e. several non-linear layers before the logits, so that
  dropping channels changes decisions and does not only jitter the last logits.

MC dropout computes the trunk once and runs the head on :meth:`Features.repeat` as one batch of N,
with the masks of :meth:`MSDLite.mc_spec` (drawn sample by sample from a private generator:
deterministic for a seed, prefix-consistent, torch's global RNG untouched). BatchNorm stays in eval
mode; :class:`MCDropout` applies a mask whatever the module's mode. The trunk holds ~80% of the
computation, so N samples cost far less than N passes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from el.classes.labels import NUM_CLASSES

# ImageNet statistics: a fixed, documented normalisation (the input is RGB in [0, 1]).
RGB_MEAN = (0.485, 0.456, 0.406)
RGB_STD = (0.229, 0.224, 0.225)


@dataclass(frozen=True, kw_only=True)
class ArchConfig:
    """Architecture hyper-parameters of :class:`MSDLite` (recorded in the model card).

    ``widths``: channels at 1/2, 1/4 and 1/8 resolution. ``trunk_dilations`` / ``head_dilations``:
    dilation of each residual block before / after the first dropout layer. ``ms_dilations``: the
    parallel branches of the multi-scale block that ends the context stack. ``dropout``: training
    drop probability of both channel-dropout layers (MC dropout sets its own per call).
    """

    name: str = "msdlite"
    num_classes: int = NUM_CLASSES
    widths: tuple[int, int, int] = (24, 48, 96)
    trunk_dilations: tuple[int, ...] = (1, 2, 4, 8)
    head_dilations: tuple[int, ...] = ()
    ms_dilations: tuple[int, ...] = (1, 3, 6, 12)
    ms_channels: int = 64  # channels of all multi-scale branches together
    decoder_channels: int = 32
    dropout: float = 0.2

    def __post_init__(self) -> None:
        if self.name != "msdlite":
            raise ValueError(f"name must be 'msdlite', got {self.name!r}")
        if len(self.widths) != 3 or min(self.widths) < 4:
            raise ValueError(f"widths must be 3 channel counts >= 4, got {self.widths!r}")
        if not (0.0 <= self.dropout < 1.0):
            raise ValueError(f"dropout must lie in [0, 1), got {self.dropout!r}")
        for attr in ("trunk_dilations", "head_dilations", "ms_dilations"):
            values = getattr(self, attr)
            if (attr == "ms_dilations" and not values) or (values and min(values) < 1):
                raise ValueError(f"{attr} must be a non-empty tuple of dilations >= 1, got {values!r}")
        if self.ms_channels < 4 or self.decoder_channels < 4:
            raise ValueError("ms_channels and decoder_channels must be >= 4")
        if self.num_classes < 2:
            raise ValueError(f"num_classes must be >= 2, got {self.num_classes!r}")

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict) -> ArchConfig:
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown architecture fields: {sorted(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


@dataclass
class MCSpec:
    """The dropout masks of one MC-dropout call: one tensor (N, C, 1, 1) per dropout layer, in call
    order, already scaled by ``1 / keep_prob``. ``used`` counts the layers that took their mask."""

    masks: list[torch.Tensor]
    used: int = 0


def draw_mc_spec(layers: list[MCDropout], n: int, keep_prob: float, seed: int) -> MCSpec:
    """Dropout masks for ``n`` MC samples of ``layers``, drawn **sample by sample** from one generator
    seeded with ``seed`` (sample i: layer 1, then layer 2...). So the first k samples of a draw of n are
    the draw of k (prefix-consistent), and the masks never touch torch's global RNG."""
    if not (0.0 < keep_prob <= 1.0):
        raise ValueError(f"keep_prob must lie in (0, 1], got {keep_prob!r}")
    gen = torch.Generator(device="cpu")
    gen.manual_seed(int(seed))
    per_sample = [[(torch.rand(m.channels, generator=gen) < keep_prob).float() / keep_prob for m in layers]
                  for _ in range(n)]
    return MCSpec([torch.stack([s[j] for s in per_sample]).view(n, -1, 1, 1) for j in range(len(layers))])


class MCDropout(nn.Module):
    """Channel dropout (whole feature maps, like ``nn.Dropout2d``) that MC sampling can drive.

    In training mode it drops channels with probability ``p`` from torch's RNG, as Dropout2d does.
    In eval mode it is the identity, unless a :class:`MCSpec` is passed: then it multiplies by the
    spec's next mask whatever the module's mode. ``channels`` is the number of feature maps it sees.
    """

    def __init__(self, p: float, channels: int) -> None:
        super().__init__()
        self.p = float(p)
        self.channels = int(channels)

    def extra_repr(self) -> str:
        return f"p={self.p}, channels={self.channels}"

    def forward(self, x: torch.Tensor, mc: MCSpec | None = None) -> torch.Tensor:
        if mc is not None:
            if mc.used >= len(mc.masks):
                raise ValueError(f"MCSpec holds {len(mc.masks)} masks, dropout layer {mc.used + 1} needs one")
            mask = mc.masks[mc.used]
            mc.used += 1
            if mask.shape != (x.shape[0], x.shape[1], 1, 1):
                raise ValueError(f"dropout mask of shape {tuple(mask.shape)} does not fit features {tuple(x.shape)}")
            return x * mask.to(dtype=x.dtype, device=x.device)
        if self.training and self.p > 0:
            return F.dropout2d(x, self.p, training=True)
        return x


def _conv_bn(cin: int, cout: int, *, stride: int = 1, dilation: int = 1, kernel: int = 3) -> nn.Sequential:
    pad = dilation * (kernel // 2)
    return nn.Sequential(
        nn.Conv2d(cin, cout, kernel, stride=stride, padding=pad, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class DilatedResidual(nn.Module):
    """Bottleneck-free residual block: 3x3 conv, 3x3 dilated conv, identity shortcut."""

    def __init__(self, channels: int, dilation: int) -> None:
        super().__init__()
        self.conv1 = _conv_bn(channels, channels)
        self.conv2 = nn.Sequential(
            nn.Conv2d(channels, channels, 3, padding=dilation, dilation=dilation, bias=False),
            nn.BatchNorm2d(channels),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.conv2(self.conv1(x)), inplace=True)


class MultiScaleBlock(nn.Module):
    """Parallel dilated 3x3 branches (several context scales at once), fused by a 1x1 conv."""

    def __init__(self, channels: int, dilations: tuple[int, ...], total: int) -> None:
        super().__init__()
        branch = max(4, total // len(dilations))
        self.branches = nn.ModuleList(_conv_bn(channels, branch, dilation=d) for d in dilations)
        self.fuse = _conv_bn(branch * len(dilations), channels, kernel=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.fuse(torch.cat([b(x) for b in self.branches], dim=1))


@dataclass
class Features:
    """What :meth:`MSDLite.trunk` hands to :meth:`MSDLite.head`."""

    deep: torch.Tensor  # (B, C3, Hp/8, Wp/8)
    skip: torch.Tensor  # (B, decoder_channels, Hp/4, Wp/4): the skip connection's lateral conv
    size: tuple[int, int]  # (H, W) of the input before padding

    def repeat(self, n: int) -> Features:
        """The same features for a batch of ``n`` (the trunk ran once on a single image)."""
        if self.deep.shape[0] != 1:
            raise ValueError(f"repeat needs features of a single image, got a batch of {self.deep.shape[0]}")
        return Features(self.deep.expand(n, -1, -1, -1), self.skip.expand(n, -1, -1, -1), self.size)


class TrunkHeadNet(nn.Module):
    """What the networks split into a deterministic trunk and a stochastic head have in common.

    Subclasses define ``stride`` (the input is padded to a multiple of it), ``logit_stride``,
    ``trunk(x) -> features`` (with ``features.size``, the unpadded (H, W)) and
    ``head_logits(features, mc)``; this class gives dropout control, MC masks, ``head`` and ``forward``.
    """

    stride = 1
    logit_stride = 1
    supports_mc_spec = True  # head() accepts an MCSpec: the fast trunk-once MC-dropout path

    # -- dropout control ---------------------------------------------------------------------
    def dropout_layers(self) -> list[MCDropout]:
        return [m for m in self.modules() if isinstance(m, MCDropout)]

    def set_dropout(self, p: float) -> None:
        """Set the training-mode drop probability of every dropout layer."""
        if not (0.0 <= p < 1.0):
            raise ValueError(f"drop probability must lie in [0, 1), got {p!r}")
        for m in self.dropout_layers():
            m.p = float(p)

    def mc_spec(self, n: int, keep_prob: float, seed: int) -> MCSpec:
        """Dropout masks for ``n`` MC samples (see :func:`draw_mc_spec`)."""
        return draw_mc_spec(self.dropout_layers(), n, keep_prob, seed)

    # -- forward -----------------------------------------------------------------------------
    def padded_input(self, x: torch.Tensor, mean: torch.Tensor | float, std: torch.Tensor | float
                     ) -> tuple[torch.Tensor, tuple[int, int]]:
        """``x`` (B, 3, H, W) normalised and edge-padded to a multiple of ``stride``, and its (H, W)."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected input of shape (B, 3, H, W), got {tuple(x.shape)}")
        h, w = int(x.shape[2]), int(x.shape[3])
        ph, pw = (-h) % self.stride, (-w) % self.stride
        x = (x - mean) / std
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        return x, (h, w)

    def head_logits(self, features: Any, mc: MCSpec | None = None) -> torch.Tensor:
        raise NotImplementedError

    def head(self, features: Any, mc: MCSpec | None = None, *, crop: bool = True) -> torch.Tensor:
        """Stochastic part: logits at the padded input size (``head_logits`` upsampled by
        ``logit_stride``), cropped to the input unless ``crop=False`` (then the caller crops after its
        softmax, which is faster on a dense tensor)."""
        logits = upsample_logits(self.head_logits(features, mc), self.logit_stride)
        if not crop:
            return logits
        h, w = features.size
        return logits[:, :, :h, :w]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x))


class MSDLite(TrunkHeadNet):
    """Compact multi-scale dilated segmentation CNN (output stride 8, logits at input size)."""

    stride = 8
    logit_stride = 4  # head_logits() are at 1/4 of the padded input; head() upsamples them bilinearly

    def __init__(self, config: ArchConfig | None = None) -> None:
        super().__init__()
        self.config = config or ArchConfig()
        c1, c2, c3 = self.config.widths
        self.register_buffer("mean", torch.tensor(RGB_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(RGB_STD).view(1, 3, 1, 1), persistent=False)
        self.stem1 = _conv_bn(3, c1, stride=2)  # 1/2
        self.stem2 = nn.Sequential(_conv_bn(c1, c2, stride=2), _conv_bn(c2, c2))  # 1/4
        self.down = _conv_bn(c2, c3, stride=2)  # 1/8
        self.trunk_blocks = nn.Sequential(*(DilatedResidual(c3, d) for d in self.config.trunk_dilations))
        self.drop1 = MCDropout(self.config.dropout, c3)
        self.head_blocks = nn.Sequential(*(DilatedResidual(c3, d) for d in self.config.head_dilations))
        self.multiscale = MultiScaleBlock(c3, self.config.ms_dilations, self.config.ms_channels)
        self.drop2 = MCDropout(self.config.dropout, c3)
        cd = self.config.decoder_channels
        # Decoder, FPN style: a 3x3 conv of the 1/8 context (upsampled) plus a 3x3 lateral conv of the
        # 1/4 skip features, then BatchNorm + ReLU. The lateral term is deterministic, so the trunk
        # computes it once for all MC samples.
        self.lateral = nn.Conv2d(c2, cd, 3, padding=1, bias=False)
        self.reduce = _conv_bn(c3, cd, kernel=1)
        self.top = nn.Conv2d(cd, cd, 3, padding=1, bias=False)
        self.fuse_bn = nn.BatchNorm2d(cd)
        self.classifier = nn.Conv2d(cd, self.config.num_classes, 1)
        # NHWC ("channels_last") weights and activations: ~15-25% faster oneDNN convolutions on CPU.
        self.to(memory_format=torch.channels_last)

    # -- forward -----------------------------------------------------------------------------
    def trunk(self, x: torch.Tensor) -> Features:
        """Deterministic part: normalise, pad to a multiple of 8, stem and first context blocks."""
        x, (h, w) = self.padded_input(x, self.mean, self.std)
        x = x.contiguous(memory_format=torch.channels_last)
        skip = self.stem2(self.stem1(x))
        deep = self.trunk_blocks(self.down(skip))
        return Features(deep, self.lateral(skip), (h, w))

    def head_logits(self, features: Features, mc: MCSpec | None = None) -> torch.Tensor:
        """Stochastic part up to the classifier: logits at 1/``logit_stride`` of the padded input."""
        x = self.drop1(features.deep, mc)
        x = self.multiscale(self.head_blocks(x))
        x = self.top(self.reduce(self.drop2(x, mc)))
        skip = features.skip
        x = F.interpolate(x, size=skip.shape[2:], mode="bilinear", align_corners=False)
        x = F.relu(self.fuse_bn(x + skip), inplace=True)
        return self.classifier(x)


def upsample_logits(logits: torch.Tensor, stride: int, window: tuple[int, int, int, int] | None = None, *,
                    then: Callable[[torch.Tensor], torch.Tensor] | None = None) -> torch.Tensor:
    """Bilinear upsampling of low-resolution logits by ``stride`` (``align_corners=False``).

    ``window = (y0, y1, x0, x1)`` returns only those rows and columns of the full upsampling, with the
    same values, at the cost of the window: the low-resolution cells under it, plus a one-cell halo,
    are upsampled (a pixel's value depends only on the cells around its source point, and the
    fractional weights of a scale of exactly ``stride`` do not depend on where the crop starts).
    ``then`` (a softmax, say) is applied to the dense upsampled block before the crop: elementwise
    work is faster on a dense tensor than on a crop of one.
    """
    then = then or (lambda t: t)
    h, w = logits.shape[2] * stride, logits.shape[3] * stride
    if window is None:
        return then(F.interpolate(logits, size=(h, w), mode="bilinear", align_corners=False))
    y0, y1, x0, x1 = window
    if not (0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w):
        raise ValueError(f"window {window} is not inside the {h}x{w} upsampled logits")
    a0, a1 = max(0, y0 // stride - 1), min(logits.shape[2], -(-y1 // stride) + 1)
    b0, b1 = max(0, x0 // stride - 1), min(logits.shape[3], -(-x1 // stride) + 1)
    sub = logits[:, :, a0:a1, b0:b1]
    up = then(F.interpolate(sub, scale_factor=stride, mode="bilinear", align_corners=False))
    oy, ox = a0 * stride, b0 * stride
    return up[:, :, y0 - oy:y1 - oy, x0 - ox:x1 - ox]


def count_parameters(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))
