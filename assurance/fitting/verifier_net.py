"""The candidate verifier's network: a small CNN of its own that scores a candidate's crop "unsafe".

``VerifierNet`` reads the crop of ``el.monitors.verifier_crop`` (RGB in [0, 1], (B, 3, S, S)) and returns two
outputs: the logit of "the disc holds a forbidden ground-truth pixel" (B,) and a coarse map of forbidden-ground
logits (B, 1, S/8, S/8), the auxiliary target that teaches it where forbidden ground lies. The encoder is the
stem and the first eleven inverted-residual blocks of EfficientNet-Lite0 (down to 1/16, 112 channels), or with
``deep`` all sixteen (down to 1/32, 320 channels), started from its ImageNet weights
(``el.segmentation.lite.load_imagenet_encoder``; nothing of the segmentation network); the coarser features are
upsampled onto the 1/8 ones, fused, and pooled over the disc (largest and mean) and over the whole crop (mean) into
the logit, beside the largest forbidden logit of the map in the disc (and, with ``deep``, the 1/32 map's mean).
The input is standardised per crop (mean and spread of its pixels), so the score reads the crop's contrast and
texture rather than its absolute brightness. Flight runs the network's ONNX export (``el.monitors.verifier``).
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from el.monitors.verifier_crop import crop_disc_mask
from el.segmentation.lite import Lite0Encoder, load_imagenet_encoder

ENCODER_BLOCKS = 11  # blocks 0..10 of EfficientNet-Lite0: down to 1/16 (112 channels)
DEEP_BLOCKS = 16  # with ``deep``: blocks 11..15 too, down to 1/32 (320 channels)
TAP_8 = 4  # the last block at 1/8 (40 channels); the last at 1/16 (112 channels) ends the encoder
MAX_FUSE_LAYERS = 6  # 3x3 convolutions over the fused 1/8 map: each lets a cell see one more cell around it
STD_FLOOR = 0.02  # of the [0, 1] pixel range: a flat crop is not blown up into noise


def check_fuse_layers(n: object) -> None:
    """Refuse a count of fused-map layers that is not an integer in 1..:data:`MAX_FUSE_LAYERS`."""
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_FUSE_LAYERS:
        raise ValueError(f"fuse_layers must lie in 1..{MAX_FUSE_LAYERS}, got {n}")


def standardise(x: torch.Tensor) -> torch.Tensor:
    """Each crop (B, 3, S, S) minus its mean per channel, over its spread (all channels, at least
    :data:`STD_FLOOR`)."""
    mean = x.mean(dim=(2, 3), keepdim=True)
    std = x.flatten(1).std(dim=1).clamp_min(STD_FLOOR).view(-1, 1, 1, 1)
    return (x - mean) / std


class VerifierNet(nn.Module):
    """Crop (B, 3, S, S) in [0, 1] -> (unsafe logit (B,), forbidden-ground logits (B, 1, S/8, S/8)).

    ``size``: the crop side S (a multiple of 32 with ``deep``, else of 16); ``margin``: the crop's margin around the
    disc, as a fraction of its radius (which pixels of the map lie in the disc); ``width``: channels of the fused
    map; ``deep``: the encoder goes on to 1/32 (blocks 11-15, 320 channels, ImageNet's most semantic features), whose
    map joins the fused one and whose mean joins the pooled features; ``fuse_layers``: 3x3 convolutions over the
    fused 1/8 map (more let a cell compare its texture with its neighbours', as a shared street's crosswise
    paving differs from the square it crosses).
    """

    def __init__(self, *, size: int = 96, margin: float = 0.5, width: int = 64, deep: bool = False,
                 fuse_layers: int = 1) -> None:
        super().__init__()
        if size % (32 if deep else 16):
            raise ValueError(f"size must be a multiple of {32 if deep else 16}, got {size}")
        check_fuse_layers(fuse_layers)
        self.size, self.margin, self.width, self.deep, self.fuse_layers = size, margin, width, deep, fuse_layers
        enc = Lite0Encoder()
        self.stem = nn.Sequential(enc._conv_stem, enc._bn0)
        self.blocks = nn.ModuleList(enc._blocks[:self.depth])
        self.lat8 = nn.Conv2d(40, width, 1)
        self.lat16 = nn.Conv2d(112, width, 1)
        self.lat32 = nn.Conv2d(320, width, 1) if deep else None
        self.fuse = nn.Sequential(*(m for _ in range(fuse_layers) for m in (
            nn.Conv2d(width, width, 3, padding=1, bias=False), nn.BatchNorm2d(width), nn.ReLU(inplace=True))))
        self.aux = nn.Conv2d(width, 1, 1)
        self.cls = nn.Sequential(nn.Dropout(0.2), nn.Linear((4 if deep else 3) * width + 1, 1))
        g = size // 8
        disc = crop_disc_mask(g, margin)
        if not disc.any():  # a grid too coarse to hold a cell centre in the disc: the centre cells
            disc[(g - 1) // 2:g // 2 + 1, (g - 1) // 2:g // 2 + 1] = True
        mask = torch.from_numpy(disc).float()
        self.register_buffer("disc", mask.view(1, 1, g, g), persistent=False)

    @property
    def depth(self) -> int:
        """How many of EfficientNet-Lite0's blocks the encoder has."""
        return DEEP_BLOCKS if self.deep else ENCODER_BLOCKS

    def encoder_modules(self) -> list[nn.Module]:
        return [self.stem, *self.blocks]

    def load_imagenet(self, path: Any = None) -> dict[str, str]:
        """The encoder's ImageNet weights (EfficientNet-Lite0), through the segmentation network's loader."""
        enc = Lite0Encoder()
        provenance = load_imagenet_encoder(enc, path)
        self.stem = nn.Sequential(enc._conv_stem, enc._bn0)
        self.blocks = nn.ModuleList(enc._blocks[:self.depth])
        return provenance

    def low(self, x: torch.Tensor) -> torch.Tensor:
        """The frozen part (kept at its ImageNet weights in training): the standardised crop to the 1/8 features."""
        x = standardise(x)
        stem_conv, stem_bn = self.stem
        y = F.relu6(stem_bn(stem_conv(x)))
        for block in self.blocks[:TAP_8 + 1]:
            y = block(y)
        return y

    def mid(self, f8: torch.Tensor) -> list[torch.Tensor]:
        """The encoder's blocks after 1/8: the 1/16 features (112 channels) and, with ``deep``, the 1/32 ones (320)."""
        y = f8
        for block in self.blocks[TAP_8 + 1:ENCODER_BLOCKS]:
            y = block(y)
        out = [y]
        if self.deep:
            for block in self.blocks[ENCODER_BLOCKS:]:
                y = block(y)
            out.append(y)
        return out

    def head(self, f8: torch.Tensor, f16: torch.Tensor, f32: torch.Tensor | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """The 1/8, 1/16 (and, with ``deep``, 1/32) features to the unsafe logit and the forbidden-ground map."""
        fused = self.lat8(f8) + F.interpolate(self.lat16(f16), size=f8.shape[-2:], mode="nearest")
        deep = self.lat32(f32) if self.lat32 is not None and f32 is not None else None
        if deep is not None:
            fused = fused + F.interpolate(deep, size=f8.shape[-2:], mode="nearest")
        fused = self.fuse(fused)
        aux = self.aux(fused)
        disc = self.disc
        n = disc.sum()
        masked_max = (fused * disc - (1.0 - disc) * 1e4).amax(dim=(2, 3))
        masked_mean = (fused * disc).sum(dim=(2, 3)) / n
        whole = fused.mean(dim=(2, 3))
        aux_max = (aux * disc - (1.0 - disc) * 1e4).amax(dim=(2, 3))
        pooled = [masked_max, masked_mean, whole, aux_max] + ([] if deep is None else [deep.mean(dim=(2, 3))])
        logit = self.cls(torch.cat(pooled, dim=1)).squeeze(1)
        return logit, aux

    def high(self, f8: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The 1/8 features to the unsafe logit and the forbidden-ground map."""
        return self.head(f8, *self.mid(f8))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.high(self.low(x))
