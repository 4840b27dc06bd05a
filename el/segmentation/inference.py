"""Segmentation inference: softmax maps for working-resolution frames and full-resolution patches.

The one class here, :class:`Segmenter`, wraps any segmentation network and gives the core model
and the runtime monitors what they need (docs/architecture.md sections 3.2 and 3.6):

- :meth:`Segmenter.predict_frame`: the HD frame resized (``cv2.INTER_AREA``) to the working
  resolution of :func:`el.geometry.camera.working_size` -> softmax (8, h, w); with ``frame_flip`` the mean
  of the softmax of the frame and of its mirror image (one batch of two; the oblique view is
  left-right symmetric in distribution, and training flips too); with ``frame_scales`` the mean
  over the working-resolution frame fed to the network at several sizes (an upsampled view gives
  the stride-4 logits a finer grid: people and cars are a few pixels wide at 1024x576);
- :meth:`Segmenter.predict_patch` / :meth:`Segmenter.predict_patches`: a full-resolution crop
  segmented at its own resolution (the LHD monitor);
- :meth:`Segmenter.mc_dropout`: N softmax samples with dropout active (the MCD monitor).

Inputs are RGB uint8 arrays (H, W, 3); anything else, or an output that is not finite, raises
ValueError, which the decision loop turns into the default action. The frame steps are
:class:`el.segmentation.frame_passes.FramePasses` (shared, torch-free); without torch (the ``train`` extra) the
shipped network runs from its ONNX export in :class:`el.segmentation.onnx_segmenter.OnnxSegmenter` instead.

Plugging in another network::

    seg = Segmenter(my_module, labels=my_labels)   # any torch.nn.Module with the contract below

The contract: ``my_module(x)`` maps float RGB images ``x`` of shape (B, 3, H, W), values in
[0, 1], to logits (B, C, H, W) for any H, W >= 16, C the number of classes of the segmenter's
label set ``labels`` (8 for UAVid); normalisation and padding are the module's
business. If the module has ``supports_mc_spec = True`` and ``trunk(x)``,
``head(features, mc, crop=False)`` (logits of at least the input size; the top-left H x W are kept)
and ``mc_spec(n, keep_prob, seed)`` methods (as :class:`el.segmentation.model.MSDLite`), MC dropout
computes the trunk once and runs the head as one batch of N. Otherwise MC dropout falls back to N
full passes with the module's dropout layers (``nn.Dropout``, ``nn.Dropout2d``, ...) switched to
train mode at the requested drop probability, everything else (BatchNorm included) in eval mode,
seeded inside ``torch.random.fork_rng`` so that the global RNG is left untouched.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from el.base.deadline import checkpoint
from el.base.errors import WeightsError
from el.classes.labels import UAVID, LabelSet
from el.segmentation.batching import unit_nchw
from el.segmentation.frame_passes import MIN_SIZE, FramePasses, check_finite, check_frame_rgb
from el.segmentation.frame_tap import FrameTap, frame_tap
from el.segmentation.lazy_trunk import LazyTrunk as _LazyTrunk
from el.segmentation.lazy_trunk import resolve as _resolve
from el.segmentation.model import MCDropout, upsample_logits
from el.segmentation.onnx_engine import engine_for
from el.segmentation.patch_passes import PatchPasses
from el.segmentation.protocol import EvalProtocol, FrameOptions, card_protocol
from el.segmentation.weights import DEFAULT_WEIGHTS, card_path, load_weights

_check_rgb = check_frame_rgb
_check_finite = check_finite


def _checked(model: nn.Module, x: torch.Tensor, where: str) -> torch.Tensor:
    """``model(x)`` after a checkpoint of the decision's deadline (``el.base.deadline``)."""
    checkpoint(where)
    return model(x)


def _is_dropout(module: nn.Module) -> bool:
    return isinstance(module, (nn.modules.dropout._DropoutNd, MCDropout))


def _check_window(window: Any, h: int, w: int) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1) of a window inside an h x w patch; the whole patch for None."""
    if window is None:
        return 0, h, 0, w
    try:
        y0, y1, x0, x1 = (int(v) for v in window)
    except (TypeError, ValueError):
        raise ValueError(f"window must be (y0, y1, x0, x1), got {window!r}") from None
    if not (0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w):
        raise ValueError(f"window {window!r} is not a non-empty box inside the {h}x{w} patch")
    return y0, y1, x0, x1


SOFTMAX_BLOCK = 64
"""Pixels per row of the class-axis softmax a multiple of this (:func:`softmax_classes`): every vector width torch
dispatches to (8 lanes with AVX2, 16 with AVX-512) and every split among threads then covers whole vectors."""


def softmax_classes(logits: torch.Tensor) -> torch.Tensor:
    """Softmax over the class axis of (B, C, H, W) logits, fast for either memory layout.

    Logits with the class axis innermost (channels-last, what the torch build of the shipped network returns,
    cropped or not) are softmaxed along that axis through a permuted view, about twice as fast as
    ``softmax(dim=1)`` on that layout; the result keeps those strides (same values; numpy sees a
    strided array).

    Class-first logits (ONNX Runtime's) are softmaxed over their pixels flattened and padded to a multiple of
    :data:`SOFTMAX_BLOCK`: torch computes the last, partial vector of a row (and of each thread's share) with other
    code than the full ones, so an odd-sized patch got other last bits on an AVX2 CPU than on an AVX-512 one, and with
    one thread than with two (issue 60: a few values in 10^5; a frame of 1024 x 576 pixels was never padded).
    """
    if logits.ndim == 4 and logits.shape[1] > 1 and logits.stride(1) == 1:  # channels innermost
        return torch.softmax(logits.permute(0, 2, 3, 1), dim=-1).permute(0, 3, 1, 2)
    if logits.ndim != 4:
        return torch.softmax(logits, dim=1)
    b, c, h, w = logits.shape
    pad = -(h * w) % SOFTMAX_BLOCK
    if pad == 0:
        return torch.softmax(logits, dim=1)
    flat = torch.nn.functional.pad(logits.reshape(b, c, h * w), (0, pad))
    return torch.softmax(flat, dim=1)[:, :, : h * w].reshape(b, c, h, w)


class Segmenter(FramePasses, PatchPasses):
    """Softmax segmentation of frames and patches, with MC dropout, around one network.

    Parameters
    ----------
    model : torch.nn.Module
        The network (see the module docstring for the contract). Put in eval mode here.
    threads : int, optional
        CPU threads for torch (``torch.set_num_threads``; process-wide). None leaves torch's setting.
    device : str
        Torch device, ``"cpu"`` by default.
    card : dict, optional
        The model card of the weights (identity for reports).
    working_width : int
        Width of the working resolution (1024; the height keeps the aspect ratio).
    frames : el.segmentation.protocol.FrameOptions, optional
        How frames are segmented (None: the frame alone, ``FrameOptions()``). :meth:`load` takes them from the
        card's evaluation protocol, so the deployed network is the one the card measured:

        - ``frame_flip``: the mean softmax of the frame and its left-right mirror image (about 3x the time of one
          frame on 2 CPU cores; patches and MC dropout are unaffected);
        - ``frame_scales``: factors (1 to 2) by which the frame at the working resolution is enlarged before the
          network (bilinear); each softmax is brought back to the working resolution and they are averaged.
          ``(1.0,)``: the frame as it is;
        - ``frame_pooling``: how such a softmax comes back to the working resolution: ``"area"`` (footprint mean)
          or ``"conservative"`` (a forbidden class any source pixel shows is kept, :mod:`el.segmentation.pooling`).
    labels : LabelSet
        The classes the network's outputs are (required; :meth:`load` takes them from the card's
        ``labels`` entry, UAVid for a card without one). The core model and the monitors read them
        from the attribute :attr:`labels`.
    engine : el.segmentation.onnx_engine.OnnxEngine, optional
        ONNX Runtime for the full passes (frames, patches) of this network; None: torch. :meth:`load`
        chooses (``UAV_EL_ENGINE``, docs/architecture.md section 3.2.1); MC dropout's head stays on torch.

    Examples
    --------
    >>> import numpy as np
    >>> from el.segmentation.architectures import build_model
    >>> from el.segmentation.model import ArchConfig
    >>> from el.classes.labels import UAVID
    >>> seg = Segmenter(build_model(ArchConfig(widths=(8, 8, 8))), working_width=64, labels=UAVID)
    >>> seg.predict_frame(np.zeros((72, 128, 3), np.uint8)).shape
    (8, 36, 64)
    """

    labels: LabelSet

    def __init__(self, model: nn.Module, *, threads: int | None = None, device: str | torch.device = "cpu",
                 card: dict[str, Any] | None = None, working_width: int = 1024, frames: FrameOptions | None = None,
                 labels: LabelSet, engine: Any = None) -> None:
        if not isinstance(model, nn.Module):
            raise ValueError(f"model must be a torch.nn.Module, got {type(model).__name__}")
        if threads is not None:
            if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
                raise ValueError(f"threads must be a positive integer, got {threads!r}")
            torch.set_num_threads(threads)
        if working_width < MIN_SIZE:
            raise ValueError(f"working_width must be >= {MIN_SIZE}, got {working_width!r}")
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.card = dict(card or {})
        self.working_width = int(working_width)
        frames = frames or FrameOptions()  # checked when built
        self.frame_flip, self.frame_scales = frames.frame_flip, frames.frame_scales
        self.frame_pooling = frames.frame_pooling
        if not isinstance(labels, LabelSet):
            raise ValueError(f"labels must be a LabelSet, got {type(labels).__name__}")
        self.labels = labels
        self.fast_mc = bool(getattr(model, "supports_mc_spec", False)
                            and all(callable(getattr(model, a, None)) for a in ("trunk", "head", "mc_spec")))
        self._lock = threading.Lock()  # the fallback MC path mutates dropout modules
        # ONNX Runtime for full passes (frames, patches), or None: torch (el.segmentation.onnx_engine)
        self.engine = engine

    @classmethod
    def load(cls, weights_path: str | Path | None = None, *, threads: int | None = None,
             device: str | torch.device = "cpu", working_width: int = 1024) -> Segmenter:
        """The shipped network (``el/segmentation/weights/model.pt``) or another weights file.

        The file's SHA-256 is checked against its model card before ``torch.load(weights_only=True)``;
        a missing or altered file raises :class:`el.segmentation.weights.WeightsError`. Frames are
        segmented as the card's evaluation protocol says (``frame_flip``, ``frame_scales``; a card
        without them: the frame alone). The label set is the card's ``labels`` entry
        (:meth:`el.classes.labels.LabelSet.from_dict`) when it has one, else UAVid.
        """
        model, card = load_weights(weights_path, device=device)
        labels = UAVID
        if card.get("labels") is not None:
            try:
                labels = LabelSet.from_dict(card["labels"])
            except ValueError as err:
                where = card_path(weights_path if weights_path is not None else DEFAULT_WEIGHTS)
                raise WeightsError(f"{where}: model card 'labels': {err}") from None
        engine = None if torch.device(device).type != "cpu" else engine_for(
            weights_path if weights_path is not None else DEFAULT_WEIGHTS, card.get("weights_sha256"), threads)
        # the card's working_width is the evaluation's; the flight code keeps its own
        return cls(model, threads=threads, device=device, card=card, labels=labels, working_width=working_width,
                   engine=engine, frames=card_protocol(card).frames())

    @classmethod
    def for_protocol(cls, model: nn.Module, protocol: EvalProtocol, **kwargs: Any) -> Segmenter:
        """A segmenter of ``model`` that segments frames as an evaluation protocol says (training, card figures)."""
        return cls(model, working_width=protocol.working_width, frames=protocol.frames(), **kwargs)

    def __getstate__(self) -> dict[str, Any]:  # picklable (for worker processes): the lock is recreated
        state = self.__dict__.copy()
        del state["_lock"]
        state.pop("_trunk_template", None)
        state.pop("_pool", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state.setdefault("labels", UAVID)  # pickled before segmenters had a label set: the shipped network's
        self.__dict__.update(state)
        self._lock = threading.Lock()

    @property
    def weights_sha256(self) -> str | None:
        return self.card.get("weights_sha256")

    @property
    def has_dropout(self) -> bool:
        """Whether MC dropout can run: the network has the fast MC head or dropout layers (the fallback)."""
        return self.fast_mc or any(_is_dropout(m) for m in self.model.modules())

    @property
    def engine_name(self) -> str:
        """What runs full passes (frames, patches): ``onnx`` (ONNX Runtime) or ``torch``."""
        return "torch" if getattr(self, "engine", None) is None else "onnx"

    # -- helpers -------------------------------------------------------------------------------
    def _to_tensor(self, images: list[np.ndarray]) -> torch.Tensor:
        return torch.from_numpy(unit_nchw(images)).to(self.device)

    def _probs(self, logits: torch.Tensor, shape: tuple[int, ...], what: str) -> np.ndarray:
        if not isinstance(logits, torch.Tensor) or tuple(logits.shape) != shape:
            got = tuple(logits.shape) if isinstance(logits, torch.Tensor) else type(logits).__name__
            raise ValueError(f"{what}: model returned {got}, expected logits of shape {shape}")
        return self._probs_checked(softmax_classes(logits.float()), shape, what)

    def _engine_probs(self, logits: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
        """Softmax of ONNX Runtime's logits (a numpy array), by torch as every other pass of this segmenter."""
        with torch.inference_mode():
            return self._probs(torch.from_numpy(logits), shape, what)

    @staticmethod
    def _probs_checked(probs: torch.Tensor, shape: tuple[int, ...], what: str) -> np.ndarray:
        if tuple(probs.shape) != shape:
            raise ValueError(f"{what}: model returned {tuple(probs.shape)}, expected {shape}")
        return _check_finite(probs.cpu().numpy(), what)

    # -- prediction (frames: el.segmentation.frame_passes) --------------------------------------
    def predict_patch(self, rgb_patch: np.ndarray, *, features: Any = None) -> np.ndarray:
        """Softmax of a patch at its own resolution: ndarray (8, h, w) float32 for a (h, w, 3) uint8 patch.

        ``features``: the patch's :meth:`patch_trunk`, when the caller shares it with MC dropout.
        """
        _check_rgb(rgb_patch, "patch")
        if getattr(self, "engine", None) is not None:  # ONNX Runtime runs the full pass
            logits = features.patch_logits() if isinstance(features, _LazyTrunk) else None
            if logits is None:
                return self._predict([rgb_patch], "patch")[0]
            h, w = rgb_patch.shape[:2]
            return np.ascontiguousarray(self._probs(logits, (1, self.labels.num_classes, h, w), "patch")[0])
        if features is None:
            return self._predict([rgb_patch], "patch")[0]
        features = _resolve(features)
        h, w = rgb_patch.shape[:2]
        with torch.inference_mode():
            logits = self.model.head(features)
            return np.ascontiguousarray(self._probs(logits, (1, self.labels.num_classes, h, w), "patch")[0])

    def patch_trunk(self, rgb_patch: np.ndarray) -> Any:
        """The deterministic part of the network on a patch, computed once for several calls.

        Pass it as ``features=`` to :meth:`predict_patch` and :meth:`mc_dropout` on the **same** patch
        (a campaign judges a candidate with the softmax and three dropout rates: one trunk instead of
        four). None for a network without the trunk/head split (the calls then run in full). With the ONNX
        engine the trunk is computed only if MC dropout asks for it (the softmax runs in ONNX Runtime).
        """
        _check_rgb(rgb_patch, "patch")
        if not self.fast_mc:
            return None
        if getattr(self, "engine", None) is not None:
            return _LazyTrunk(self, rgb_patch)
        with torch.inference_mode():
            return self.model.trunk(self._to_tensor([rgb_patch]))

    def _predict(self, images: list[np.ndarray], what: str) -> np.ndarray:
        return self._run(images, what, False)[0]

    def _frame_pass(self, images: list[np.ndarray], stats: bool) -> tuple[np.ndarray, FrameTap | None]:
        return self._run(images, "frame", stats)

    def _run(self, images: list[np.ndarray], what: str, stats: bool) -> tuple[np.ndarray, FrameTap | None]:
        """The softmax of a batch and, with ``stats``, the statistics of its first image from this very pass (one
        pass: the trunk is read where the network or the ONNX export has one)."""
        h, w = images[0].shape[:2]
        with torch.inference_mode():
            features = None
            if getattr(self, "engine", None) is not None:
                batch = unit_nchw(images)
                if stats and getattr(self.engine, "trunk_names", None):  # one pass, the trunk's outputs kept
                    raw, features = self.engine.with_trunk(batch)
                    logits = torch.from_numpy(raw)
                else:
                    logits = torch.from_numpy(self.engine.logits(batch))
            elif stats and self.fast_mc:  # one pass, split: the gates read its trunk
                features = self.model.trunk(self._to_tensor(images))
                logits = self.model.head(features)
            else:
                logits = self.model(self._to_tensor(images))
            # C-contiguous: frames feed the core model's OpenCV and numpy code.
            probs = np.ascontiguousarray(self._probs(logits, (len(images), self.labels.num_classes, h, w), what))
            return probs, (frame_tap(logits, features) if stats else None)

    # -- Monte-Carlo dropout -------------------------------------------------------------------
    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int, *,
                   features: Any = None, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """N softmax samples of a patch with dropout active (drop probability ``1 - keep_prob``).

        The trunk runs once and the head once on a batch of ``n`` (fast path), BatchNorm in eval
        mode. The masks are drawn sample by sample from a private generator seeded with ``seed``
        (torch's global RNG is not touched), so the result is deterministic for a seed and
        prefix-consistent: the first k samples of an n-sample call are the k-sample call (up to the
        float rounding of batched convolutions, ~1e-7). ``keep_prob = 1`` returns ``n`` copies of
        :meth:`predict_patch` (standard deviation exactly 0).

        Parameters
        ----------
        rgb_patch : ndarray of shape (h, w, 3), uint8
        n : int
            Number of samples, >= 1.
        keep_prob : float
            The paper's rho, in (0, 1]; 1 means no dropout (all samples equal).
        seed : int
            Seed of the dropout masks.
        features : optional
            The patch's :meth:`patch_trunk` (shared with other calls on the same patch).
        window : (y0, y1, x0, x1), optional
            Return only these rows and columns of the patch (a monitor needs its disc's box): the
            same scores, to float rounding, as slicing the full result, at the cost of the window.

        Returns
        -------
        ndarray of shape (n, 8, h, w), float32 (h, w: the window's size when one is given).
        """
        _check_rgb(rgb_patch, "patch")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if not (isinstance(keep_prob, (int, float, np.floating)) and 0.0 < float(keep_prob) <= 1.0):
            raise ValueError(f"keep_prob must lie in (0, 1], got {keep_prob!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        n, keep, seed = int(n), float(keep_prob), int(seed)
        h, w = rgb_patch.shape[:2]
        shape = (n, self.labels.num_classes, h, w)
        y0, y1, x0, x1 = _check_window(window, h, w)
        if keep == 1.0:  # no dropout: every sample is the deterministic softmax (exactly, std 0)
            probs = self.predict_patch(rgb_patch, features=features)[None, :, y0:y1, x0:x1]
            return np.repeat(probs, n, axis=0)
        x = self._to_tensor([rgb_patch])
        if not self.fast_mc:
            return self._mc_fallback(x, n, 1.0 - keep, seed, shape)[:, :, y0:y1, x0:x1]
        spec = self.model.mc_spec(n, keep, seed)
        features = _resolve(features)
        with torch.inference_mode():
            if features is None:
                features = self.model.trunk(x)
            if window is not None and hasattr(self.model, "head_logits") and hasattr(self.model, "logit_stride"):
                low = self.model.head_logits(features.repeat(n), spec)
                probs = upsample_logits(low.float(), self.model.logit_stride, (y0, y1, x0, x1), then=softmax_classes)
                return self._probs_checked(probs, (n, self.labels.num_classes, y1 - y0, x1 - x0), "MC dropout")
            # Softmax of the padded logits (dense channels-last), then the crop: the fast order.
            logits = self.model.head(features.repeat(n), spec, crop=False)
            if logits.ndim != 4 or logits.shape[2] < h or logits.shape[3] < w:
                raise ValueError(f"MC dropout: model returned {tuple(logits.shape)}, expected logits "
                                 f"of at least {shape}")
            probs = softmax_classes(logits.float())[:, :, y0:y1, x0:x1]
            return self._probs_checked(probs, (n, self.labels.num_classes, y1 - y0, x1 - x0), "MC dropout")

    def _mc_fallback(self, x: torch.Tensor, n: int, p: float, seed: int, shape: tuple[int, ...]) -> np.ndarray:
        drops = [m for m in self.model.modules() if _is_dropout(m)]
        if not drops:
            raise ValueError("MC dropout: the model has no dropout layers")
        with self._lock:
            saved = [(m, m.p, m.training) for m in drops]
            try:
                with torch.random.fork_rng(devices=[]), torch.inference_mode():
                    torch.manual_seed(seed)
                    for m in drops:
                        m.p = p
                        m.train()
                    logits = torch.cat([_checked(self.model, x, "MC dropout") for _ in range(n)], dim=0)
            finally:
                for m, old_p, training in saved:
                    m.p = old_p
                    m.train(training)
        return self._probs(logits, shape, "MC dropout")
