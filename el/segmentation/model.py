"""The shipped segmentation network: a compact multi-scale dilated CNN with channel dropout.

In the spirit of MSDnet (the paper's model): a strided stem, a stack of dilated residual blocks
that see several context scales at 1/8 resolution, a parallel multi-dilation block, and a decoder
that fuses a 1/4-resolution skip connection before upsampling the logits to the input size.

Contract (shared by every model the toolkit accepts, DESIGN section 5.1):
``forward(x)`` maps RGB float images ``x`` of shape (B, 3, H, W), values in [0, 1], to logits of
shape (B, 8, H, W) for any H, W >= 8 (the network pads internally to a multiple of its stride and
crops back). Mean/std normalisation happens inside the model.

For Monte-Carlo dropout the forward pass is split in two:

- ``trunk(x) -> Features``: the deterministic part, everything before the first dropout layer;
- ``head(features, mc=None) -> logits``: the stochastic rest (both dropout layers sit here, the first
  one in the middle of the context stack, so dropping channels changes decisions, not only the last
  logits).

``head`` accepts a batch of features larger than the one ``trunk`` produced only through
:meth:`Features.repeat`, which is how MC dropout computes the trunk once and runs the head N times
as one batch. Dropout masks come from :class:`MCDropout` (an explicit generator, so MC sampling is
deterministic for a seed and never touches torch's global RNG); BatchNorm stays in eval mode.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
import torch.nn.functional as F
from torch import nn

from el.labels import NUM_CLASSES

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
    skip_channels: int = 32
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
    """How the dropout layers behave in one MC-dropout call.

    ``p``: drop probability (``1 - keep_prob``). ``generator``: source of the masks. ``replay``:
    masks to use instead of drawing (one per dropout layer, in call order; for verification).
    ``recorded``: the masks actually used, appended in call order.
    """

    p: float
    generator: torch.Generator | None = None
    replay: list[torch.Tensor] | None = None
    recorded: list[torch.Tensor] = field(default_factory=list)


class MCDropout(nn.Module):
    """Channel dropout (whole feature maps, like ``nn.Dropout2d``) that MC sampling can drive.

    In training mode it drops channels with probability ``p`` from torch's RNG, as Dropout2d does.
    In eval mode it is the identity, unless a :class:`MCSpec` is passed: then it drops with the
    spec's probability and generator (or replays the spec's masks) whatever the module's mode.
    """

    def __init__(self, p: float) -> None:
        super().__init__()
        self.p = float(p)

    def extra_repr(self) -> str:
        return f"p={self.p}"

    def forward(self, x: torch.Tensor, mc: MCSpec | None = None) -> torch.Tensor:
        if mc is not None:
            if mc.replay is not None:
                mask = mc.replay[len(mc.recorded)]
            else:
                keep = 1.0 - mc.p
                if keep >= 1.0:
                    mask = torch.ones(x.shape[0], x.shape[1], 1, 1, dtype=x.dtype, device=x.device)
                else:
                    probs = torch.full((x.shape[0], x.shape[1], 1, 1), keep, dtype=x.dtype)
                    mask = torch.bernoulli(probs, generator=mc.generator).to(x.device) / keep
            mc.recorded.append(mask)
            return x * mask
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

    def __init__(self, channels: int, dilations: tuple[int, ...]) -> None:
        super().__init__()
        branch = max(8, channels // len(dilations))
        self.branches = nn.ModuleList(_conv_bn(channels, branch, dilation=d) for d in dilations)
        self.fuse = _conv_bn(branch * len(dilations), channels, kernel=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.fuse(torch.cat([b(x) for b in self.branches], dim=1))


@dataclass
class Features:
    """What :meth:`MSDLite.trunk` hands to :meth:`MSDLite.head`."""

    deep: torch.Tensor  # (B, C3, Hp/8, Wp/8)
    skip: torch.Tensor  # (B, skip_channels, Hp/4, Wp/4), already projected
    size: tuple[int, int]  # (H, W) of the input before padding

    def repeat(self, n: int) -> Features:
        """The same features for a batch of ``n`` (the trunk ran once on a single image)."""
        if self.deep.shape[0] != 1:
            raise ValueError(f"repeat needs features of a single image, got a batch of {self.deep.shape[0]}")
        return Features(self.deep.expand(n, -1, -1, -1), self.skip.expand(n, -1, -1, -1), self.size)


class MSDLite(nn.Module):
    """Compact multi-scale dilated segmentation CNN (output stride 8, logits at input size)."""

    stride = 8
    supports_mc_spec = True  # head() accepts an MCSpec: the fast trunk-once MC-dropout path

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
        self.drop1 = MCDropout(self.config.dropout)
        self.head_blocks = nn.Sequential(*(DilatedResidual(c3, d) for d in self.config.head_dilations))
        self.multiscale = MultiScaleBlock(c3, self.config.ms_dilations)
        self.drop2 = MCDropout(self.config.dropout)
        self.skip_proj = _conv_bn(c2, self.config.skip_channels, kernel=1)
        self.reduce = _conv_bn(c3, self.config.skip_channels, kernel=1)
        self.decoder = _conv_bn(2 * self.config.skip_channels, self.config.decoder_channels)
        self.classifier = nn.Conv2d(self.config.decoder_channels, self.config.num_classes, 1)

    # -- dropout control ---------------------------------------------------------------------
    def dropout_layers(self) -> list[MCDropout]:
        return [m for m in self.modules() if isinstance(m, MCDropout)]

    def set_dropout(self, p: float) -> None:
        """Set the training-mode drop probability of every dropout layer."""
        if not (0.0 <= p < 1.0):
            raise ValueError(f"drop probability must lie in [0, 1), got {p!r}")
        for m in self.dropout_layers():
            m.p = float(p)

    # -- forward -----------------------------------------------------------------------------
    def trunk(self, x: torch.Tensor) -> Features:
        """Deterministic part: normalise, pad to a multiple of 8, stem and first context blocks."""
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"expected input of shape (B, 3, H, W), got {tuple(x.shape)}")
        h, w = int(x.shape[2]), int(x.shape[3])
        ph, pw = (-h) % self.stride, (-w) % self.stride
        x = (x - self.mean) / self.std
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        skip = self.stem2(self.stem1(x))
        deep = self.trunk_blocks(self.down(skip))
        return Features(deep, self.skip_proj(skip), (h, w))

    def head(self, features: Features, mc: MCSpec | None = None) -> torch.Tensor:
        """Stochastic part: dropout, dilated context, multi-scale block, dropout, decoder, logits."""
        x = self.drop1(features.deep, mc)
        x = self.multiscale(self.head_blocks(x))
        x = self.reduce(self.drop2(x, mc))
        skip = features.skip
        x = F.interpolate(x, size=skip.shape[2:], mode="bilinear", align_corners=False)
        x = self.decoder(torch.cat([x, skip], dim=1))
        logits = self.classifier(x)
        hp, wp = skip.shape[2] * 4, skip.shape[3] * 4
        logits = F.interpolate(logits, size=(hp, wp), mode="bilinear", align_corners=False)
        h, w = features.size
        return logits[:, :, :h, :w]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x))


def build_model(config: ArchConfig | dict | None = None) -> MSDLite:
    """An untrained :class:`MSDLite` from a config (or its dict form, as stored in a model card)."""
    if isinstance(config, dict):
        config = ArchConfig.from_dict(config)
    return MSDLite(config)


def count_parameters(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))
