"""The evaluation protocol a model card records, which is also how the network is deployed.

The protocol is data (recorded in the model card) so that ``uav-el model-card --verify`` can redo
exactly the same computation (:mod:`assurance.fitting.network.evaluation`), and :meth:`Segmenter.load
<el.segmentation.inference.Segmenter.load>` segments frames the way the card's figures were measured.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from el.segmentation.pooling import check_pooling


@dataclass(frozen=True, kw_only=True)
class EvalProtocol:
    """Which figures the model card holds: working width, HD patches per frame, their side and seed.

    ``frame_flip``: frames are segmented as the mean softmax of the frame and its mirror image (see
    :class:`~el.segmentation.inference.Segmenter`). It is part of how the network is deployed:
    :meth:`Segmenter.load` follows the card's protocol, so the figures describe the flight code.

    ``frame_scales``: the frame at the working resolution is fed to the network resized by each of
    these factors (1.25: 1280x720 for 1024x576) and the softmax, brought back to the working
    resolution, averaged over them. Only the working-resolution image is used: an upsampled input
    gives the network's stride-4 logits a finer grid, which small objects (people, cars) need.

    ``frame_pooling``: how such a softmax comes back to the working resolution: ``area`` (mean over
    each working pixel's footprint) or ``conservative`` (no forbidden class that a source pixel shows
    is lost; :mod:`el.segmentation.pooling`).
    """

    working_width: int = 1024
    hd_patches: int = 2
    hd_patch_size: int = 384
    seed: int = 12345
    frame_flip: bool = False
    frame_scales: tuple[float, ...] = (1.0,)
    frame_pooling: str = "area"

    def __post_init__(self) -> None:
        if self.working_width < 16 or self.hd_patches < 0 or self.hd_patch_size < 16:
            raise ValueError(f"invalid evaluation protocol: {self}")
        if not isinstance(self.frame_flip, bool):
            raise ValueError(f"frame_flip must be true or false, got {self.frame_flip!r}")
        object.__setattr__(self, "frame_scales", check_frame_scales(self.frame_scales))
        check_pooling(self.frame_pooling)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), **self.frame_options()}

    def frame_options(self) -> dict[str, Any]:
        """How frames are segmented (:data:`FRAME_OPTIONS`), JSON-ready."""
        return {"frame_flip": self.frame_flip, "frame_scales": list(self.frame_scales),
                "frame_pooling": self.frame_pooling}

    def frames(self) -> FrameOptions:
        """How frames are segmented, as :class:`~el.segmentation.inference.Segmenter` takes it."""
        return FrameOptions(frame_flip=self.frame_flip, frame_scales=self.frame_scales,
                            frame_pooling=self.frame_pooling)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvalProtocol:
        """From a card's ``evaluation.protocol`` (what an older card lacks takes its default)."""
        out: dict[str, Any] = {}
        for k, v in data.items():
            if k in FRAME_OPTIONS:  # checked in __post_init__
                out[k] = v
            elif k in cls.__dataclass_fields__:
                out[k] = int(v)
        return cls(**out)


MAX_FRAME_SCALE = 2.0
FRAME_OPTIONS = ("frame_flip", "frame_scales", "frame_pooling")  # the protocol's keys that deployment follows too


def check_frame_scales(scales: Any) -> tuple[float, ...]:
    """``frame_scales`` as a tuple of floats; ValueError unless a list of 1 to 4 distinct numbers in [1, 2].

    Factors are upsamplings (the frame is already at the working resolution; a smaller view would
    only lose detail), so the input is enlarged bilinearly and the softmax brought down by area.
    """
    numbers = isinstance(scales, list | tuple) and all(
        isinstance(s, int | float) and not isinstance(s, bool) for s in scales)
    out = tuple(float(s) for s in scales) if numbers else ()
    if not 1 <= len(out) <= 4 or len(set(out)) != len(out) or not all(1.0 <= s <= MAX_FRAME_SCALE for s in out):
        raise ValueError(f"frame_scales must be a list of 1 to 4 distinct factors in [1, {MAX_FRAME_SCALE:g}], "
                         f"got {scales!r}")
    return out


@dataclass(frozen=True, kw_only=True)
class FrameOptions:
    """How a segmenter segments a frame (:data:`FRAME_OPTIONS`, as :class:`EvalProtocol` records them):
    ``frame_flip`` (the mean softmax of the frame and its mirror image), ``frame_scales`` (the factors the working
    frame is enlarged by before the network, their softmax brought back and averaged) and ``frame_pooling`` (how
    it comes back: ``area`` or ``conservative``). Checked when built (ValueError naming the option)."""

    frame_flip: bool = False
    frame_scales: tuple[float, ...] = (1.0,)
    frame_pooling: str = "area"

    def __post_init__(self) -> None:
        if not isinstance(self.frame_flip, bool):
            raise ValueError(f"frame_flip must be true or false, got {self.frame_flip!r}")
        object.__setattr__(self, "frame_scales", check_frame_scales(self.frame_scales))
        object.__setattr__(self, "frame_pooling", check_pooling(self.frame_pooling))


def card_protocol(card: dict[str, Any]) -> EvalProtocol:
    """The evaluation protocol a model card records (defaults for what an older card lacks).

    It is also how the network is deployed: :meth:`Segmenter.load` segments frames as it says.
    """
    return EvalProtocol.from_dict((card.get("evaluation") or {}).get("protocol") or {})
