"""Training of the candidate verifier (``assurance.fitting.verifier_net.VerifierNet``) on candidate crops.

The loss is the class-balanced binary cross-entropy of "unsafe" plus the auxiliary forbidden-ground map (a cell is
forbidden when any ground-truth pixel under it is). The stem and the blocks down to 1/8 keep their ImageNet weights,
so each training crop goes through them once per view (the first view as it is, the others augmented), under ONNX
Runtime, and the steps train the rest on those features: training fits on 2 CPU cores. Augmentations are none of
the evaluation's perturbations (no brightness, fog, blur, shifted or dead rows): a horizontal flip, a small zoom and
shift, a colour balance and saturation change, and light sensor noise; ``augment="optics"`` adds what another lens,
codec or exposure gives (a lower resolution, a slight defocus, JPEG artefacts, a tone curve), so the verifier does not
rest on the finest texture alone. Selection: the step with the best AUROC of
the held-out split's core-model candidates (never the test split), evaluated every ``eval_every`` steps; training
stops at ``steps`` or after ``minutes``, whichever comes first.
"""

from __future__ import annotations

import copy
import io
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from assurance.fitting.verifier_data import CropSet
from assurance.fitting.verifier_net import TAP_8, VerifierNet, check_fuse_layers
from el.monitors.verifier_crop import MAX_MARGIN
from el.segmentation.onnx_engine import open_session

FROZEN = ("encoder", "low")  # encoder: every encoder block keeps its ImageNet weights; low: down to 1/8 only
AUGMENTS = ("colour", "optics")  # colour: flip, zoom, colour balance, noise; optics: and lens, codec and exposure
FROZEN_BLOCKS = TAP_8 + 2  # the stem and blocks 0..4 (down to 1/8) keep their ImageNet weights (of encoder_modules)


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """How the verifier trains; the defaults are ``uav-el fit-verifier``'s (the shipped verifier's recipe is the
    command and configuration its record, ``verifier.json``, carries)."""

    size: int = 256  # a paver of a 4K frame still shows at 256 px, not at 64 (docs/results.md)
    margin: float = 1.0  # a radius of context around the disc (docs/results.md)
    steps: int = 3000
    batch: int = 64
    lr: float = 1e-3
    encoder_lr_scale: float = 0.3
    weight_decay: float = 1e-4
    aux_weight: float = 0.5
    eval_every: int = 250
    views: int = 1
    frozen: str = "encoder"  # "encoder": every encoder block keeps its ImageNet weights; "low": down to 1/8 only
    deep: bool = True  # the encoder goes on to 1/32 (VerifierNet's ``deep``)
    fuse_layers: int = 1  # 3x3 convolutions over the fused 1/8 map (VerifierNet's ``fuse_layers``)
    augment: str = "colour"  # the augmented views' set (AUGMENTS); the first view is never augmented
    rank_weight: float = 0.0  # weight of the within-scene ranking loss (:class:`ScenePairs`); 0: none
    anchor: float = 0.0  # with frozen "low": weight of the pull of the learning blocks' features to ImageNet's; 0: none
    minutes: float | None = None
    seed: int = 0
    threads: int = 2

    def __post_init__(self) -> None:
        for name in ("size", "steps", "batch", "eval_every", "threads", "views"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.size % (32 if self.deep else 16):
            raise ValueError(f"size must be a multiple of {32 if self.deep else 16}, got {self.size}")
        if not 0.0 <= self.margin <= MAX_MARGIN:
            raise ValueError(f"margin must lie in [0, {MAX_MARGIN:g}] radii, got {self.margin}")
        if not (math.isfinite(self.lr) and self.lr > 0.0):
            raise ValueError(f"lr must be a positive number, got {self.lr}")
        if not (math.isfinite(self.rank_weight) and self.rank_weight >= 0.0):
            raise ValueError(f"rank_weight must be a number >= 0, got {self.rank_weight}")
        if not (math.isfinite(self.anchor) and self.anchor >= 0.0):
            raise ValueError(f"anchor must be a number >= 0, got {self.anchor}")
        if self.anchor and self.frozen != "low":
            raise ValueError("anchor pulls the learning encoder blocks to their ImageNet features: it needs frozen "
                             "'low' (with the whole encoder frozen they never move)")
        if self.minutes is not None and not self.minutes > 0.0:
            raise ValueError(f"minutes must be > 0, got {self.minutes}")
        check_fuse_layers(self.fuse_layers)
        if self.frozen not in FROZEN:
            raise ValueError(f"frozen must be one of {', '.join(FROZEN)}, got {self.frozen!r}")
        if self.augment not in AUGMENTS:
            raise ValueError(f"augment must be one of {', '.join(AUGMENTS)}, got {self.augment!r}")
        if self.augment != "colour" and self.views < 2:
            raise ValueError(f"augment {self.augment!r} changes the augmented views, and there are none: "
                             "it needs views >= 2 (the first view is the crop as it is)")


@dataclass
class TrainResult:
    model: VerifierNet
    best_step: int
    best_auroc: float
    curve: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    steps_run: int = 0


def to_size(crops: np.ndarray, size: int) -> np.ndarray:
    """Crops (n, s, s, 3) uint8 resampled to ``size`` (area down, bilinear up); the same array when already so."""
    if crops.shape[1] == size:
        return crops
    interp = cv2.INTER_AREA if crops.shape[1] > size else cv2.INTER_LINEAR
    return np.stack([cv2.resize(c, (size, size), interpolation=interp) for c in crops]) if len(crops) else \
        np.zeros((0, size, size, 3), np.uint8)


def optics(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """What another lens, codec or exposure does to a crop (uint8 RGB, s x s), each with probability one half: a
    lower resolution (down to 50-90% and back), a slight isotropic defocus (sigma 0.4-1.5 px), JPEG artefacts
    (quality 35-90) and a tone curve (gamma 0.7-1.4). None is an evaluation perturbation (those are an additive
    brightness, fog, a vertical motion blur of 10-50 px, shifted rows and dead pixels); the defocus and the
    vertical blur are both blurs, which docs/results.md weighs where it reports what this set gives."""
    s = img.shape[0]
    if rng.random() < 0.5:
        small = max(8, round(s * rng.uniform(0.5, 0.9)))
        img = cv2.resize(cv2.resize(img, (small, small), interpolation=cv2.INTER_AREA), (s, s),
                         interpolation=cv2.INTER_LINEAR)
    if rng.random() < 0.5:
        img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.4, 1.5))
    if rng.random() < 0.5:
        ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 91))])
        if ok:
            img = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    if rng.random() < 0.5:
        gamma = math.exp(rng.uniform(math.log(0.7), math.log(1.4)))
        lut = np.clip(np.round(255.0 * (np.arange(256) / 255.0) ** gamma), 0, 255).astype(np.uint8)
        img = cv2.LUT(np.ascontiguousarray(img), lut)
    return np.ascontiguousarray(img)


def augment(crops: np.ndarray, aux: np.ndarray, size: int, rng: np.random.Generator, *, kind: str = "colour"
            ) -> tuple[np.ndarray, np.ndarray]:
    """A training batch: crops (n, s, s, 3) uint8 and their aux maps (n, g, g) -> float (n, 3, size, size) in
    [0, 1] and (n, size/8, size/8) aux targets (flip, zoom and shift applied to both alike); ``kind`` "optics" adds
    :func:`optics` (the aux targets stay: none of it moves a pixel)."""
    n, s = crops.shape[:2]
    g = size // 8
    out = np.empty((n, size, size, 3), np.float32)
    tgt = np.empty((n, g, g), np.float32)
    ga = aux.shape[1]
    for i in range(n):
        side = s * rng.uniform(0.93, 1.0)
        x0, y0 = rng.uniform(0.0, s - side, size=2)
        m = np.array([[side / size, 0.0, x0], [0.0, side / size, y0]], np.float32)
        img = cv2.warpAffine(crops[i], m, (size, size), flags=cv2.INTER_AREA | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_REFLECT)
        k = ga / s
        ma = np.array([[side * k / g, 0.0, x0 * k], [0.0, side * k / g, y0 * k]], np.float32)
        a = cv2.warpAffine(aux[i], ma, (g, g), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                           borderMode=cv2.BORDER_REFLECT)
        if rng.random() < 0.5:
            img, a = img[:, ::-1], a[:, ::-1]
        if kind == "optics":
            img = optics(img, rng)
        x = img.astype(np.float32) / 255.0
        x = x * rng.uniform(0.92, 1.08, size=3).astype(np.float32)  # colour balance
        grey = x.mean(axis=2, keepdims=True)
        x = grey + (x - grey) * np.float32(rng.uniform(0.75, 1.25))  # saturation
        x = x + rng.normal(0.0, rng.uniform(0.0, 0.015), size=x.shape).astype(np.float32)  # sensor noise
        out[i] = np.clip(x, 0.0, 1.0)
        tgt[i] = a
    return out.transpose(0, 3, 1, 2), (tgt > 1e-3).astype(np.float32)


def as_input(crops: np.ndarray) -> torch.Tensor:
    """Crops (n, S, S, 3) uint8 -> (n, 3, S, S) float in [0, 1]."""
    return torch.from_numpy(np.ascontiguousarray(crops.transpose(0, 3, 1, 2))).float().div_(255.0)


@torch.inference_mode()
def predict(model: VerifierNet, crops: np.ndarray, *, batch: int = 128) -> np.ndarray:
    """P(unsafe) of crops (n, S, S, 3) uint8 at the model's size: (n,) float64."""
    model.eval()
    out = [torch.sigmoid(model(as_input(crops[i:i + batch]))[0]).double().numpy()
           for i in range(0, len(crops), batch)]
    return np.concatenate(out) if out else np.zeros(0)


def auroc(y: np.ndarray, p: np.ndarray) -> float:
    from sklearn.metrics import roc_auc_score

    return float(roc_auc_score(y, p)) if 0 < y.sum() < y.size else math.nan


def frozen_session(model: VerifierNet, *, encoder: bool, threads: int) -> Any:
    """The frozen part of ``model`` under ONNX Runtime: float crops (n, 3, S, S) in [0, 1] -> the 1/8 features and,
    when the whole ``encoder`` is frozen, the coarser ones (:meth:`VerifierNet.mid`). ONNX Runtime runs
    EfficientNet's depthwise convolutions about nine times faster than torch on a CPU, and this pass is most of a
    training run's time."""

    class Frozen(torch.nn.Module):
        def __init__(self, net: VerifierNet) -> None:
            super().__init__()
            self.net = net

        def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
            f8 = self.net.low(x)
            return (f8, *self.net.mid(f8)) if encoder else (f8,)

    names = ["f8", "f16", "f32"][:3 if model.deep else 2] if encoder else ["f8"]
    frozen = Frozen(model).eval()  # the model too; the export restores the wrapper's mode, and with it the model's
    return open_session(onnx_bytes(frozen, model.size, names), "the verifier's frozen encoder", threads)


OPSET = 17


def onnx_bytes(module: torch.nn.Module, size: int, outputs: list[str]) -> bytes:
    """The ONNX bytes of ``module`` on crops (B, 3, ``size``, ``size``) named ``crops``, its outputs named
    ``outputs``, the batch dimension free (the TorchScript exporter, opset :data:`OPSET`)."""
    buf = io.BytesIO()
    with warnings.catch_warnings():  # the TorchScript exporter's deprecation notices
        warnings.simplefilter("ignore")
        torch.onnx.export(module, (torch.rand(2, 3, size, size),), buf, input_names=["crops"], output_names=outputs,
                          dynamic_axes={"crops": {0: "batch"}, **{o: {0: "batch"} for o in outputs}},
                          opset_version=OPSET, dynamo=False)
    return buf.getvalue()


def low_features(session: Any, x: np.ndarray, *, batch: int = 64) -> list[torch.Tensor]:
    """The frozen part's features (:func:`frozen_session`) of float crops (n, 3, S, S) in [0, 1], as float16: the
    1/8 features (n, 40, S/8, S/8) and, when the whole encoder is frozen, the 1/16 ones (n, 112, S/16, S/16) and
    with ``deep`` the 1/32 ones (n, 320, S/32, S/32)."""
    names = [o.name for o in session.get_outputs()]
    parts: list[list[torch.Tensor]] = [[] for _ in names]
    for i in range(0, len(x), batch):
        out = session.run(names, {"crops": np.ascontiguousarray(x[i:i + batch], np.float32)})
        for part, f in zip(parts, out, strict=True):
            part.append(torch.from_numpy(f).half())
    return [torch.cat(part) for part in parts]


def feature_arrays(like: Sequence[torch.Tensor], n: int, spill: Path | None) -> list[torch.Tensor]:
    """Arrays for ``n`` crops' features shaped as ``like``'s rows: in memory, or with ``spill`` (a folder) in files
    there, memory-mapped, so that the page cache holds what fits and the rest stays on disk."""
    if spill is None:
        return [torch.empty((n, *f.shape[1:]), dtype=f.dtype) for f in like]
    return [torch.from_numpy(np.memmap(spill / f"features-{i}.f16", dtype=np.float16, mode="w+",
                                       shape=(n, *f.shape[1:])))
            for i, f in enumerate(like)]


def cached_views(session: Any, crops: CropSet, cfg: TrainConfig, rng: np.random.Generator,
                 log: Callable[[str], None], *, spill: Path | None = None
                 ) -> tuple[list[torch.Tensor], torch.Tensor, np.ndarray]:
    """Every training crop in ``cfg.views`` views (the first as it is, the others augmented), through the frozen part
    once: their features (:func:`low_features`), aux targets and truth. The frozen part never changes, so each view
    is computed once. The features are written into arrays sized once (about 180 kB a crop at 256 px, deep), not
    joined at the end, which would take twice their memory; with ``spill`` (a folder) those arrays are files there
    (:func:`feature_arrays`): 900 scenes' 72,000 crops hold 13 GB of features, too much for a 24 GB machine beside
    the rest."""
    plain = to_size(crops.crops, cfg.size)
    g = cfg.size // 8
    n = len(plain) * cfg.views
    if n == 0:
        raise ValueError("no training crops (no core-model candidate in the training scenes)")
    levels: list[torch.Tensor] = []
    auxes, ys = torch.empty((n, g, g), dtype=torch.float32), np.empty(n, bool)
    at = 0
    for v in range(cfg.views):
        for i in range(0, len(plain), 512):
            part = slice(i, i + 512)
            if v == 0:
                x = plain[part].transpose(0, 3, 1, 2).astype(np.float32) / 255.0
                a = np.stack([cv2.resize(t, (g, g), interpolation=cv2.INTER_AREA) for t in crops.aux[part]])
                a = (a > 1e-3).astype(np.float32)
            else:
                x, a = augment(crops.crops[part], crops.aux[part], cfg.size, rng, kind=cfg.augment)
            out = low_features(session, x)
            levels = levels or feature_arrays(out, n, spill)
            k = len(x)
            for dst, f in zip(levels, out, strict=True):
                dst[at:at + k] = f
            auxes[at:at + k] = torch.from_numpy(a)
            ys[at:at + k] = crops.unsafe[part]
            at += k
        log(f"view {v + 1} of {cfg.views} through the frozen encoder")
    return levels, auxes, ys


class ScenePairs:
    """Pairs (unsafe crop, safe crop) of one scene, the orders the score walk needs right (it lands on the frame's
    lowest-scored candidate, ``el.monitors.walk``), drawn without listing them: a scene's pairs grow as the square
    of its crops. A draw takes an unsafe crop whose scene has a safe one, then one of those safe crops, uniformly."""

    def __init__(self, scene: np.ndarray, unsafe: np.ndarray) -> None:
        scene, unsafe = np.asarray(scene), np.asarray(unsafe, bool)
        safe = np.flatnonzero(~unsafe)
        self.safe = safe[np.argsort(scene[safe], kind="stable")]
        scenes, self.start, self.count = np.unique(scene[self.safe], return_index=True, return_counts=True)
        bad = np.flatnonzero(unsafe)
        self.bad = bad[np.isin(scene[bad], scenes)]  # scenes with a safe crop
        self.pos = np.searchsorted(scenes, scene[self.bad])

    def __len__(self) -> int:
        return len(self.bad)

    def draw(self, rng: np.random.Generator, k: int) -> np.ndarray:
        """(k, 2) crop indices (unsafe, safe), both of one scene."""
        i = rng.integers(0, len(self.bad), k)
        p = self.pos[i]
        j = self.safe[self.start[p] + (rng.random(k) * self.count[p]).astype(np.int64)]
        return np.stack([self.bad[i], j], axis=1)


def _optimiser(model: VerifierNet, cfg: TrainConfig) -> torch.optim.Optimizer:
    frozen = len(model.encoder_modules()) if cfg.frozen == "encoder" else FROZEN_BLOCKS
    for mod in model.encoder_modules()[:frozen]:
        for p in mod.parameters():
            p.requires_grad_(False)
    enc = [p for m in model.blocks[TAP_8 + 1:] for p in m.parameters() if p.requires_grad]
    skip = {id(p) for p in enc} | {id(p) for m in model.encoder_modules() for p in m.parameters()}
    head = [p for p in model.parameters() if id(p) not in skip]
    groups = [{"params": enc, "lr": cfg.lr * cfg.encoder_lr_scale}, {"params": head, "lr": cfg.lr}]
    return torch.optim.AdamW([g for g in groups if g["params"]], weight_decay=cfg.weight_decay)


def _forward(model: VerifierNet, feats: Sequence[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """The logit and map from cached features: the 1/8 ones alone (the rest of the encoder trains) or all levels."""
    levels = [f.float() for f in feats]
    return model.high(levels[0]) if len(levels) == 1 else model.head(*levels)


def _anchored_forward(model: VerifierNet, f8: torch.Tensor, targets: Sequence[torch.Tensor],
                      scales: Sequence[float]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The logit and map from the 1/8 features through the learning blocks, and the anchor: the mean squared gap
    between those blocks' features and their ImageNet ones (``targets``), per level over its ImageNet variance
    (``scales``), averaged over the levels (the blocks' batch norms in eval mode, so it starts at nought).
    Fine-tuning forgets what ImageNet's features are robust to (docs/results.md measured a motion-blurred AUROC of
    0.82 fall to 0.70); the anchor keeps the features near them."""
    f8 = f8.float()
    mid = model.mid(f8)
    logit, aux = model.head(f8, *mid)
    gaps = [F.mse_loss(f, t.float()) / s for f, t, s in zip(mid, targets, scales, strict=True)]
    return logit, aux, torch.stack(gaps).mean()


@torch.inference_mode()
def _held_out_auroc(model: VerifierNet, feats: Sequence[torch.Tensor], y: np.ndarray) -> float:
    model.eval()
    p = torch.cat([torch.sigmoid(_forward(model, [f[i:i + 512] for f in feats])[0])
                   for i in range(0, len(feats[0]), 512)])
    return auroc(y, p.double().numpy())


def train_verifier(train: CropSet, val: CropSet, cfg: TrainConfig, *, pretrained: bool = True,
                   log: Callable[[str], None] = print, spill: Path | None = None) -> TrainResult:
    """Train on ``train`` (every crop), select on ``val``'s core-model candidates by AUROC; ``spill``: a folder the
    training crops' features are kept in as files (:func:`cached_views`).

    The stem and the blocks down to 1/8 keep their ImageNet weights; each training crop goes through them once per
    view, under ONNX Runtime (:func:`cached_views`), and the steps train the rest (the coarser blocks and the head) on
    those features."""
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    model = VerifierNet(size=cfg.size, margin=cfg.margin, deep=cfg.deep, fuse_layers=cfg.fuse_layers)
    if pretrained:
        model.load_imagenet()
    t0 = time.perf_counter()
    session = frozen_session(model, encoder=cfg.frozen == "encoder" or bool(cfg.anchor), threads=cfg.threads)
    feats, aux_t, y = cached_views(session, train, cfg, rng, log, spill=spill)
    vsel = val.is_candidate
    vfeats = low_features(session, to_size(val.crops[vsel], cfg.size).transpose(0, 3, 1, 2).astype(np.float32)
                          / 255.0)
    targets: list[torch.Tensor] = []
    scales: list[float] = []
    if cfg.anchor:  # the ImageNet features of the learning blocks are targets, not inputs
        feats, targets, vfeats = feats[:1], feats[1:], vfeats[:1]
        scales = [max(float(t[:4096].float().var()), 1e-6) for t in targets]
    vy = val.unsafe[vsel]
    opt = _optimiser(model, cfg)
    base = [g["lr"] for g in opt.param_groups]
    pos = float(y.mean())
    pos_weight = torch.tensor((1.0 - pos) / max(pos, 1e-6))
    yt = torch.from_numpy(y.astype(np.float32))
    pairs = ScenePairs(train.scene, train.unsafe) if cfg.rank_weight else None
    best = TrainResult(copy.deepcopy(model), 0, -1.0)
    step = 0
    for step in range(1, cfg.steps + 1):
        model.train()
        if targets:  # the encoder's batch norms keep ImageNet's statistics: the anchor compares like with like
            for block in model.blocks:
                block.eval()
        frac = step / cfg.steps
        for g, lr in zip(opt.param_groups, base, strict=True):
            g["lr"] = lr * (min(1.0, step / 50) * 0.5 * (1.0 + math.cos(math.pi * frac)))
        idx = torch.from_numpy(rng.integers(0, len(y), cfg.batch))
        gap = None
        if targets:
            logit, aux, gap = _anchored_forward(model, feats[0][idx], [t[idx] for t in targets], scales)
        else:
            logit, aux = _forward(model, [f[idx] for f in feats])
        loss = F.binary_cross_entropy_with_logits(logit, yt[idx], pos_weight=pos_weight)
        if gap is not None:
            loss = loss + cfg.anchor * gap
        loss = loss + cfg.aux_weight * F.binary_cross_entropy_with_logits(aux[:, 0], aux_t[idx])
        if pairs is not None and len(pairs):  # an unsafe crop above a safe one of its scene, in any of the views
            pick = pairs.draw(rng, max(1, cfg.batch // 2))
            pick = pick + len(train.unsafe) * rng.integers(0, cfg.views, pick.shape)
            lp = _forward(model, [f[torch.from_numpy(pick.reshape(-1))] for f in feats])[0].view(-1, 2)
            loss = loss + cfg.rank_weight * F.softplus(lp[:, 1] - lp[:, 0]).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        out_of_time = cfg.minutes is not None and time.perf_counter() - t0 > 60.0 * cfg.minutes
        if step % cfg.eval_every == 0 or step == cfg.steps or out_of_time:
            score = _held_out_auroc(model, vfeats, vy)
            point = {"step": step, "loss": loss.item(), "val_auroc": score, "seconds": time.perf_counter() - t0}
            if gap is not None:
                point["anchor_gap"] = gap.item()
            best.curve.append(point)
            extra = "" if gap is None else f", anchor gap {gap.item():.4f}"
            log(f"step {step}: loss {loss.item():.4f}{extra}, held-out AUROC {score:.4f} "
                f"({time.perf_counter() - t0:.0f} s)")
            if score > best.best_auroc:
                best.model, best.best_step, best.best_auroc = copy.deepcopy(model), step, score
        if out_of_time:
            break
    best.seconds, best.steps_run = time.perf_counter() - t0, step
    best.model.eval()
    return best
