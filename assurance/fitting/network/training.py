"""Train the segmentation network at both scales it meets in use; keep the best model on validation.

Each step draws (seeded by ``(seed, step)``, so a resumed run follows the same path):

- ``batch`` random square crops of ``crop`` px from working-resolution frames (the core model's view);
- full-resolution crops of a side drawn in ``[hd_crop_min, hd_crop_max]`` (the LHD monitor's view of a
  candidate), as many as fit ``hd_pixels`` pixels, cut from seeded full-resolution regions.

Loss: class-weighted cross-entropy (inverse square root of the class frequency, see
:func:`assurance.fitting.network.data.class_weights`), optionally plus the Lovász-softmax IoU surrogate
(``loss="ce+lovasz"``, :mod:`assurance.fitting.network.losses`), the mean of both scales. Optimiser: AdamW,
linear warm-up
then cosine decay. Augmentation: :data:`assurance.fitting.network.data.AUGMENTATIONS` only; none of the
evaluation perturbations (brightness, fog, motion blur, shifted rows, dead rows).

Every ``checkpoint_every`` steps the model, optimiser, scheduler and step are written atomically to
the checkpoint file (default ``<weights>.ckpt``); ``RunOptions(resume=True)`` continues from there. With
validation data the network is evaluated every ``eval_every`` steps (mIoU at working resolution and
on HD patches) and the best one is written to the weights file with its model card; the card is
completed at the end (data hashes, seeds, timing, figures, confusion matrices and the per-pixel
baseline).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from assurance.fitting.network import data as D
from assurance.fitting.network.baseline import evaluate_baseline
from assurance.fitting.network.batches import prefetched, sample_batch
from assurance.fitting.network.checkpoint import checkpoint_path, config_changes, load_checkpoint, save_checkpoint
from assurance.fitting.network.evaluation import evaluate, selection_score
from assurance.fitting.network.losses import describe as describe_loss
from assurance.fitting.network.losses import segmentation_loss
from assurance.fitting.network.train_config import TrainConfig, lr_factor
from assurance.fitting.network.weights_io import save_weights, write_card
from el.segmentation.architectures import AnyArch, arch_from_dict, build_model
from el.segmentation.inference import Segmenter
from el.segmentation.model import count_parameters
from el.segmentation.weights import load_weights, read_card

Progress = Callable[..., Iterable]
Log = Callable[[str], None]


def resolve_device(device: str | torch.device) -> torch.device:
    """A torch device for training; ValueError if it names an accelerator this machine lacks."""
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise ValueError(f"unknown device {device!r}: {exc}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r}: torch {torch.__version__} sees no CUDA GPU on this machine")
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"device {device!r}: no Apple MPS device on this machine")
    if dev.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"device {device!r}: training supports cpu, cuda and mps")
    return dev


def training_loss(model: torch.nn.Module, batches: tuple, weights: torch.Tensor, kind: str = "ce"
                  ) -> torch.Tensor:
    """The step's loss (:func:`assurance.fitting.network.losses.segmentation_loss`), mean over the scales present."""
    losses = [segmentation_loss(model(x), y, weights, kind) for x, y in (b for b in batches if b is not None)]
    return torch.stack(losses).mean()


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How a training run proceeds, besides what shapes it (:class:`TrainConfig`, recorded in the checkpoint).

    Parameters
    ----------
    resume : bool
        Continue from the checkpoint (same configuration and data required). Without it, an existing
        checkpoint is an error rather than silently overwritten.
    cache_dir : folder, optional
        Where prepared samples are cached (None: no cache).
    checkpoint_file : file, optional
        The resumable state (default ``<weights>.ckpt``, see :func:`checkpoint_path`).
    threads : int, optional
        torch CPU threads (also the data-preparation threads).
    init_weights : file, optional
        Warm start: begin from these weights (SHA-256 checked, same architecture as ``config.arch``)
        instead of a random initialisation; ``config.init_sha256`` must name them. The card records
        the parent and the steps behind it.
    device : str
        Where the optimisation runs (``"cpu"``, ``"cuda"``...). Model selection evaluates there; the
        card's figures are then recomputed on the CPU, where the flight code runs, so that
        ``uav-el model-card --verify`` reproduces them.
    stop_at : int, optional
        End the run after this step, evaluating and completing the card there, with the learning-rate
        schedule still that of ``config.steps`` (a run cut short to fit a time budget; the card
        records ``stopped_at``). Not part of the configuration, so a run can be resumed with it.
    prefetch : int
        Threads that draw the next steps' mini-batches while the current one trains (0: none). The
        batches are a pure function of ``(seed, step)``, so this changes speed only.
    """

    resume: bool = False
    cache_dir: str | Path | None = None
    checkpoint_file: str | Path | None = None
    threads: int | None = None
    init_weights: str | Path | None = None
    device: str | torch.device = "cpu"
    stop_at: int | None = None
    prefetch: int = 0


def train(train_dir: str | Path, weights_path: str | Path, *, val_dir: str | Path | None = None,
          config: TrainConfig | None = None, options: RunOptions | None = None, progress: Progress | None = None,
          log: Log | None = None, on_eval: Callable[[list[dict[str, Any]]], None] | None = None) -> dict[str, Any]:
    """Train on a UAVid-layout folder, write the weights and their model card; returns the card.

    Parameters
    ----------
    train_dir, val_dir : folder
        UAVid-layout datasets (labels required). Without ``val_dir`` no model selection happens: the
        final network is written and the card has no evaluation.
    weights_path : file
        The weights file to write (its card goes next to it).
    config : TrainConfig, optional
        What shapes the run (None: the defaults).
    options : RunOptions, optional
        How the run proceeds: resume, cache, checkpoint, threads, warm start, device, early stop, prefetch
        (None: the defaults).
    progress : callable, optional
        ``progress(iterable, total=..., desc=...)`` wrapper (a progress bar).
    log : callable, optional
        Receives one-line messages.
    on_eval : callable, optional
        Receives the history (loss and validation figures so far) after each evaluation, e.g. to draw
        the training curve.
    """
    config = config or TrainConfig()
    o = options or RunOptions()
    resume, cache_dir, threads = o.resume, o.cache_dir, o.threads
    weights_path = Path(weights_path)
    say = log or (lambda _msg: None)
    device = resolve_device(o.device)
    if threads is not None:
        torch.set_num_threads(threads)
    io_threads = threads or torch.get_num_threads()
    ckpt_path = _checkpoint_target(weights_path, o.checkpoint_file, resume)

    started = time.perf_counter()
    data_ids, train_set, val_set, state = _load_data(train_dir, val_dir, config, ckpt_path if resume else None,
                                                     cache_dir, io_threads, progress, say)
    prep_seconds = time.perf_counter() - started
    freq = D.class_frequencies(train_set)
    weights = torch.from_numpy(D.class_weights(freq))

    model, parent, encoder_init = _build_model(config, o.init_weights, device, say)
    optimizer, scheduler, early, run = _optimiser(model, config, state, device, say)
    end = _end_step(config, o.stop_at, run.step, ckpt_path)
    card_base = functools.partial(_card_base, config, data_ids, freq, weights, parent, encoder_init, device, end)
    fit = _Fit(config, device, model, optimizer, scheduler, early, weights.to(device), weights_path, ckpt_path,
               data_ids, card_base, o.prefetch)
    _run_steps(fit, run, train_set, val_set, end, progress=progress, on_eval=on_eval, say=say)
    card = _final_card(model, run, config, weights_path, card_base(), val_set, device, say)
    card["training"].update(_run_record(run, model, config, end, prep_seconds))
    if config.baseline_pixels and val_set:
        say("fitting the per-pixel baseline")
        card["baseline"] = _baseline(train_set, val_set, config, card["evaluation"]["working_resolution"]["miou"])
    write_card(weights_path, card)
    return card


def _checkpoint_target(weights_path: Path, checkpoint_file: str | Path | None, resume: bool) -> Path:
    """The checkpoint file of the run; ValueError if one exists and the run does not resume it."""
    ckpt_path = Path(checkpoint_file) if checkpoint_file is not None else checkpoint_path(weights_path)
    if ckpt_path.exists() and not resume:
        raise ValueError(f"{ckpt_path}: a checkpoint exists; resume it (--resume) or delete it")
    return ckpt_path


@dataclass
class _RunState:
    """What a run carries from step to step (and through its checkpoint)."""

    step: int = 0
    best_score: float = -math.inf
    best_step: int | None = None
    history: list[dict[str, Any]] = field(default_factory=list)
    train_seconds: float = 0.0


@dataclass
class _Fit:
    """What every step of a run uses: the network, its optimiser, the loss weights, and where the run writes."""

    config: TrainConfig
    device: torch.device
    model: torch.nn.Module
    optimizer: torch.optim.Optimizer
    scheduler: torch.optim.lr_scheduler.LRScheduler
    early: list[torch.nn.Parameter]  # frozen for the first ``freeze_early_steps`` steps
    loss_weights: torch.Tensor  # the class weights, on ``device``
    weights_path: Path
    ckpt_path: Path
    data_ids: dict[str, Any]
    card_base: Callable[[], dict[str, Any]]
    prefetch: int = 0  # threads drawing the next steps' mini-batches (RunOptions.prefetch)


def _optimiser(model: torch.nn.Module, config: TrainConfig, state: dict[str, Any] | None, device: torch.device,
               say: Log) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler,
                                  list[torch.nn.Parameter], _RunState]:
    """AdamW with its learning-rate schedule, the early parameters, and the run's state (from ``state`` if resuming)."""
    optimizer = torch.optim.AdamW(_param_groups(model, config), lr=config.lr, weight_decay=config.weight_decay)
    early = list(model.early_parameters()) if hasattr(model, "early_parameters") else []
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: lr_factor(s, config))
    run = _RunState()
    if state is not None:
        run = _restore(state, model, optimizer, scheduler, device)
        say(f"resuming from step {run.step} of {config.steps}")
    return optimizer, scheduler, early, run


def _run_steps(fit: _Fit, run: _RunState, train_set: list[D.Prepared], val_set: list[D.Prepared], end: int, *,
               progress: Progress | None, on_eval: Callable[[list[dict[str, Any]]], None] | None, say: Log) -> None:
    """Optimise steps ``run.step`` to ``end``, evaluating (and selecting) every ``evaluation_interval`` steps
    and at the end, and checkpointing every ``checkpoint_every`` steps, after an improvement and at the end."""
    config = fit.config
    interval = config.evaluation_interval
    window: list[float] = []
    steps = range(run.step, end)
    iterator = progress(steps, total=len(steps), desc="train") if progress is not None else steps
    draws = prefetched(lambda s: sample_batch(train_set, config, s), steps, workers=fit.prefetch,
                       depth=2 * fit.prefetch)
    fit.model.train()
    for step, batches in zip(iterator, draws, strict=True):
        loss, seconds = _optimise(fit, batches, step)
        run.train_seconds += seconds
        window.append(loss.item())
        done = step + 1
        last = done == end
        improved = False
        if done % interval == 0 or last:
            entry: dict[str, Any] = {"step": done, "loss": float(np.mean(window)),
                                     "seconds_per_step": run.train_seconds / done}
            window = []
            if val_set:
                improved = _select(fit, run, entry, val_set)
            run.history.append(entry)
            if on_eval is not None:
                on_eval(run.history)
            say(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in entry.items()))
        if improved or done % config.checkpoint_every == 0 or last:
            save_checkpoint(fit.ckpt_path, {
                "step": done, "model": fit.model.state_dict(), "optimizer": fit.optimizer.state_dict(),
                "scheduler": fit.scheduler.state_dict(), "config": config.to_dict(), "data": fit.data_ids,
                **_checkpoint_record(run)})


def _checkpoint_record(run: _RunState) -> dict[str, Any]:
    """The run's state as its checkpoint keeps it (beside the model, optimiser and scheduler)."""
    return {"best_score": run.best_score, "best_step": run.best_step, "history": run.history,
            "train_seconds": run.train_seconds}


def _run_record(run: _RunState, model: torch.nn.Module, config: TrainConfig, end: int,
                prep_seconds: float) -> dict[str, Any]:
    """What the card's ``training`` section learns at the end: selection, history, timing, size."""
    return {
        "best_step": run.best_step, "history": run.history, "train_seconds": round(run.train_seconds, 1),
        "seconds_per_step": round(run.train_seconds / max(1, end), 3),
        "stopped_at": end if end < config.steps else None,
        "prepare_seconds": round(prep_seconds, 1), "threads": torch.get_num_threads(),
        "parameters": count_parameters(model),
    }


def _load_data(train_dir: str | Path, val_dir: str | Path | None, config: TrainConfig, resume_from: Path | None,
               cache_dir: str | Path | None, io_threads: int, progress: Progress | None, say: Log
               ) -> tuple[dict[str, Any], list[D.Prepared], list[D.Prepared], dict[str, Any] | None]:
    """Hash the data, check a resumed checkpoint against it and the configuration, prepare the samples."""
    say(f"hashing {train_dir}" + (f" and {val_dir}" if val_dir else ""))
    train_manifest = D.dataset_manifest(train_dir, threads=io_threads)
    val_manifest = D.dataset_manifest(val_dir, threads=io_threads) if val_dir is not None else None
    data_ids = {"train": train_manifest.describe(), "val": val_manifest.describe() if val_manifest else None}
    state = None
    if resume_from is not None:
        state = load_checkpoint(resume_from)
        changes = config_changes(state["config"], config.to_dict())
        if changes:
            raise ValueError(f"{resume_from}: the checkpoint was made with another configuration: "
                             + "; ".join(changes))
        for split in ("train", "val"):
            old, new = state["data"].get(split), data_ids[split]
            if (old or {}).get("sha256") != (new or {}).get("sha256"):
                raise ValueError(f"{resume_from}: the {split} data changed since the checkpoint "
                                 f"({(old or {}).get('sha256')} -> {(new or {}).get('sha256')})")
    train_set = D.load_dataset(train_manifest, config.prep_params(), cache_dir=cache_dir, threads=io_threads,
                               progress=progress)
    val_set = (D.load_dataset(val_manifest, D.protocol_prep(config.eval_protocol), cache_dir=cache_dir,
                              threads=io_threads, progress=progress) if val_manifest else [])
    return data_ids, train_set, val_set, state


def _build_model(config: TrainConfig, init_weights: str | Path | None, device: torch.device, say: Log
                 ) -> tuple[torch.nn.Module, dict[str, Any] | None, Any]:
    """The seeded network on ``device``: warm-started, or with its encoder's ImageNet weights; and their records."""
    torch.manual_seed(config.seed)
    model = build_model(config.arch)
    parent = _warm_start(model, init_weights, config) if init_weights is not None else None
    encoder_init = None
    if parent is None and hasattr(model, "load_pretrained"):
        say("loading the ImageNet weights of the encoder")
        encoder_init = model.load_pretrained()
    elif parent is not None:
        encoder_init = parent.get("encoder_init")
    model.to(device)
    if init_weights is None and config.init_sha256 is not None:
        raise ValueError("config.init_sha256 is set but no init_weights were given")
    return model, parent, encoder_init


def _restore(state: dict[str, Any], model: torch.nn.Module, optimizer: torch.optim.Optimizer,
             scheduler: torch.optim.lr_scheduler.LRScheduler, device: torch.device) -> _RunState:
    """Load a checkpoint into the model, optimiser and scheduler; the run's state at its step."""
    model.load_state_dict(state["model"])
    model.to(device)
    optimizer.load_state_dict(state["optimizer"])
    scheduler.load_state_dict(state["scheduler"])
    return _RunState(step=int(state["step"]), best_score=float(state.get("best_score", -math.inf)),
                     best_step=state.get("best_step"), history=list(state.get("history", [])),
                     train_seconds=float(state.get("train_seconds", 0.0)))


def _end_step(config: TrainConfig, stop_at: int | None, start_step: int, ckpt_path: Path) -> int:
    """The step the run ends after (``stop_at`` or ``config.steps``), checked against the resumed step."""
    end = config.steps if stop_at is None else int(stop_at)
    if not 0 < end <= config.steps:
        raise ValueError(f"stop_at must lie in 1..{config.steps}, got {stop_at!r}")
    if start_step >= end and start_step < config.steps:
        raise ValueError(f"{ckpt_path}: the checkpoint is at step {start_step}, past stop_at {end}")
    return end


def _card_base(config: TrainConfig, data_ids: dict[str, Any], freq: np.ndarray, weights: torch.Tensor,
               parent: dict[str, Any] | None, encoder_init: Any, device: torch.device, end: int) -> dict[str, Any]:
    """The card's ``training`` section as known before the run ends (a fresh dict each call)."""
    return {"training": {
        "data": data_ids, "seed": config.seed, "config": config.to_dict(), "steps": config.steps,
        "augmentations": list(D.AUGMENTATIONS),
        "not_used_augmentations": ["brightness", "fog", "motion_blur", "shifted_pixels", "dead_rows"],
        "loss": describe_loss(config.loss),
        "class_frequencies": [float(f) for f in freq], "class_weights": [float(w) for w in weights],
        "torch_version": torch.__version__, "init": parent, "encoder_init": encoder_init,
        "device": _device_name(device),
        "total_steps": end + (parent["total_steps"] if parent else 0),
    }}


def _optimise(fit: _Fit, batches: tuple, step: int) -> tuple[torch.Tensor, float]:
    """One optimisation step (dropout masks seeded by ``(seed, step)``); its loss and its seconds."""
    tick = time.perf_counter()
    config, device, model = fit.config, fit.device, fit.model
    torch.manual_seed(int(np.random.default_rng([config.seed, 2, step]).integers(2**62)))  # dropout masks
    batches = tuple(None if b is None else (b[0].to(device, non_blocking=True), b[1].to(device, non_blocking=True))
                    for b in batches)
    for p in fit.early:  # the early encoder stays as pretrained for the first steps (a pure function of the step)
        p.requires_grad_(step >= config.freeze_early_steps)
    loss = training_loss(model, batches, fit.loss_weights, config.loss)
    if not torch.isfinite(loss):
        raise ValueError(f"training diverged at step {step}: loss is {float(loss)}")
    fit.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 5.0)
    fit.optimizer.step()
    fit.scheduler.step()
    return loss, time.perf_counter() - tick


def _select(fit: _Fit, run: _RunState, entry: dict[str, Any], val_set: list[D.Prepared]) -> bool:
    """Evaluate on the validation set into ``entry``; write the weights and card if best so far (True)."""
    tick = time.perf_counter()
    config, model = fit.config, fit.model
    model.eval()
    figures = evaluate(Segmenter.for_protocol(model, config.eval_protocol, device=fit.device,
                                              labels=D.TRAINING_LABELS), val_set)
    model.train()
    score = selection_score(figures)
    entry.update({"val_miou_working": figures["working_resolution"]["miou"],
                  "val_miou_hd": figures["hd_patches"]["miou"], "score": score,
                  "eval_seconds": time.perf_counter() - tick})
    if not score > run.best_score:  # (a NaN score never wins)
        return False
    run.best_score, run.best_step = score, entry["step"]
    save_weights(model, fit.weights_path, card={**fit.card_base(), "evaluation": {
        "data": fit.data_ids["val"], "protocol": config.eval_protocol.to_dict(), "step": entry["step"], **figures}})
    return True


def _final_card(model: torch.nn.Module, run: _RunState, config: TrainConfig, weights_path: Path,
                base: dict[str, Any], val_set: list[D.Prepared], device: torch.device, say: Log) -> dict[str, Any]:
    """The card of the final network (no validation) or of the selected one, its figures from the CPU."""
    if not val_set:
        return save_weights(model, weights_path, card={**base, "evaluation": None})
    card = read_card(weights_path)
    if device.type != "cpu":
        say(f"re-evaluating the selected weights (step {run.best_step}) on the CPU")
        selected, _ = load_weights(weights_path)
        cpu_figures = evaluate(Segmenter.for_protocol(selected, config.eval_protocol, labels=D.TRAINING_LABELS),
                               val_set)
        card["evaluation"].update(cpu_figures)
        card["evaluation"]["selection_device"] = _device_name(device)
    return card


def _baseline(train_set: list[D.Prepared], val_set: list[D.Prepared], config: TrainConfig,
              cnn_miou: float | None) -> dict[str, Any]:
    """The per-pixel baseline's figures, with its mIoU gap to the network's."""
    baseline = evaluate_baseline(
        [s.image for s in train_set], [s.labels for s in train_set],
        [s.image for s in val_set], [s.labels for s in val_set],
        max_pixels=config.baseline_pixels, seed=config.seed)
    base = baseline["miou"]
    baseline["miou_gap_to_cnn"] = None if cnn_miou is None or base is None else cnn_miou - base
    return baseline


def _param_groups(model: torch.nn.Module, config: TrainConfig) -> list[dict[str, Any]]:
    """Optimiser parameter groups: a pretrained encoder learns at ``encoder_lr_scale`` times the rate."""
    if not hasattr(model, "encoder_parameters") or config.encoder_lr_scale == 1.0:
        return [{"params": list(model.parameters())}]
    encoder = {id(p) for p in model.encoder_parameters()}
    rest = [p for p in model.parameters() if id(p) not in encoder]
    return [{"params": list(model.encoder_parameters()), "lr": config.lr * config.encoder_lr_scale},
            {"params": rest}]


def _device_name(device: torch.device) -> str:
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    return device.type


def _warm_start(model: torch.nn.Module, init_weights: str | Path, config: TrainConfig) -> dict[str, Any]:
    """Load the parent weights into ``model``; returns the card's record of the parent."""
    parent, card = load_weights(init_weights)
    if card["weights_sha256"] != config.init_sha256:
        raise ValueError(f"{init_weights}: SHA-256 {card['weights_sha256']} is not the configured init_sha256 "
                         f"{config.init_sha256}")
    if arch_from_dict(card["architecture"]) != config.arch:
        raise ValueError(f"{init_weights}: architecture {card['architecture']} differs from this run's "
                         f"{config.arch.to_dict()}")
    model.load_state_dict(parent.state_dict())
    training = card.get("training") or {}
    return {"path": str(init_weights), "weights_sha256": card["weights_sha256"],
            "steps": training.get("steps"), "total_steps": training.get("total_steps", training.get("steps") or 0),
            "encoder_init": training.get("encoder_init")}


def init_untrained(arch: AnyArch | None = None, seed: int = 0) -> torch.nn.Module:
    """A seeded, randomly initialised network (benchmarks and tests)."""
    torch.manual_seed(seed)
    return build_model(arch).eval()
