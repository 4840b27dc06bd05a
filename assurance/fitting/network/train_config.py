"""What shapes a training run (recorded in its checkpoint and model card) and its learning-rate schedule."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from assurance.fitting.network import data as D
from assurance.fitting.network.losses import LOSSES
from el.segmentation.architectures import AnyArch, arch_from_dict
from el.segmentation.model import ArchConfig
from el.segmentation.protocol import EvalProtocol


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Everything that shapes a training run (recorded in the checkpoint and the model card)."""

    steps: int = 1500
    batch: int = 4  # working-resolution crops per step
    crop: int = 256  # their side (px)
    hd_pixels: int = 4 * 256 * 256  # full-resolution crop pixels per step
    hd_crop_min: int = 192
    hd_crop_max: int = 448
    hd_regions: int = 4  # full-resolution regions kept per training image
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup: int = 50
    eval_every: int = 0  # 0: evaluate 4 times, evenly spaced
    checkpoint_every: int = 25
    seed: int = 0
    working_width: int = 1024
    arch: AnyArch = field(default_factory=ArchConfig)
    augment: D.AugmentParams = field(default_factory=D.AugmentParams)
    eval_protocol: EvalProtocol = field(default_factory=EvalProtocol)
    baseline_pixels: int = 200_000  # 0: skip the per-pixel baseline
    init_sha256: str | None = None  # SHA-256 of the weights a warm start begins from (None: random init)
    loss: str = "ce"  # "ce" or "ce+lovasz" (see assurance.fitting.network.losses)
    encoder_lr_scale: float = 1.0  # a pretrained encoder's learning rate, as a fraction of lr
    freeze_early_steps: int = 0  # steps during which a pretrained encoder's stem and 1/4 stages stay frozen

    def __post_init__(self) -> None:
        positive = ("steps", "batch", "crop", "hd_crop_min", "hd_crop_max", "checkpoint_every")
        for name in positive:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if self.crop < 16 or self.hd_crop_min < 16:
            raise ValueError("crop and hd_crop_min must be >= 16 px")
        if self.hd_crop_max < self.hd_crop_min:
            raise ValueError(f"hd_crop_max ({self.hd_crop_max}) must be >= hd_crop_min ({self.hd_crop_min})")
        for name in ("hd_pixels", "hd_regions", "warmup", "eval_every", "baseline_pixels", "freeze_early_steps"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise ValueError(f"lr must be positive, got {self.lr!r}")
        if not (0 < self.encoder_lr_scale <= 1 and math.isfinite(self.encoder_lr_scale)):
            raise ValueError(f"encoder_lr_scale must lie in (0, 1], got {self.encoder_lr_scale!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")
        if self.working_width != self.eval_protocol.working_width:
            raise ValueError("working_width and eval_protocol.working_width must agree")

    @property
    def region_size(self) -> int:
        """Side of the kept full-resolution regions: room for the largest crop after scale jitter."""
        return int(math.ceil(self.hd_crop_max * (1 + self.augment.scale_jitter)))

    @property
    def evaluation_interval(self) -> int:
        return self.eval_every or max(1, math.ceil(self.steps / 4))

    def prep_params(self) -> D.PrepParams:
        return D.PrepParams(working_width=self.working_width, regions=self.hd_regions if self.hd_pixels else 0,
                            region_size=self.region_size, seed=self.seed)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["arch"] = self.arch.to_dict()
        out["eval_protocol"] = self.eval_protocol.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        data = dict(data)
        arch = arch_from_dict(data.pop("arch"))
        augment = D.AugmentParams(**data.pop("augment"))
        protocol = EvalProtocol.from_dict(data.pop("eval_protocol"))
        return cls(arch=arch, augment=augment, eval_protocol=protocol, **data)


def steps_for_epochs(images: int, epochs: int, batch: int) -> int:
    """Steps for ``epochs`` passes, one pass = every training image once as a working-resolution crop."""
    if images < 1 or epochs < 1 or batch < 1:
        raise ValueError(f"images, epochs and batch must be positive, got {images}, {epochs}, {batch}")
    return epochs * math.ceil(images / batch)


def lr_factor(step: int, config: TrainConfig) -> float:
    """The learning rate at ``step`` as a fraction of ``config.lr``: linear warm-up, then cosine decay to 5%."""
    if step < config.warmup:
        return (step + 1) / config.warmup
    span = max(1, config.steps - config.warmup)
    t = min(1.0, (step - config.warmup) / span)
    return 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t))
