"""Training losses: class-weighted cross-entropy, optionally plus the Lovász-softmax IoU surrogate.

Cross-entropy rewards confident pixels and, class-weighted, pushes rare classes (humans) beyond
what maximises their IoU. The Lovász-softmax loss (Berman, Triki and Blaschko, CVPR 2018) is the
convex (Lovász) extension of the Jaccard loss ``1 - IoU`` to class probabilities: on one-hot
predictions it equals ``1 - IoU`` exactly, so descending it optimises the mIoU the model card
reports. It is computed over all pixels of a batch (the dataset-level IoU, not a per-image one) and
averaged over the classes present in the batch's labels.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

LOSSES = ("ce", "ce+lovasz")


def lovasz_softmax(probs: torch.Tensor, labels: torch.Tensor) -> torch.Tensor:
    """Mean Lovász-softmax loss over the classes present in ``labels``.

    ``probs``: (B, C, H, W) class probabilities; ``labels``: (B, H, W) class ids in [0, C).
    Returns a scalar; 0 when the batch holds no pixel.
    """
    if probs.dim() != 4 or labels.shape != (probs.shape[0], *probs.shape[2:]):
        raise ValueError(f"expected probs (B, C, H, W) and labels (B, H, W), got {tuple(probs.shape)} "
                         f"and {tuple(labels.shape)}")
    num_classes = probs.shape[1]
    flat = probs.permute(1, 0, 2, 3).reshape(num_classes, -1)  # (C, N)
    if flat.shape[1] == 0:
        return probs.sum() * 0.0
    fg = F.one_hot(labels.reshape(-1).long(), num_classes).T.to(flat.dtype)  # (C, N)
    present = fg.sum(1) > 0
    errors = (fg - flat).abs()
    errors_sorted, order = torch.sort(errors, dim=1, descending=True)
    fg_sorted = fg.gather(1, order)
    total = fg_sorted.sum(1, keepdim=True)
    intersection = total - fg_sorted.cumsum(1)
    union = total + (1.0 - fg_sorted).cumsum(1)
    jaccard = 1.0 - intersection / union
    grad = torch.cat([jaccard[:, :1], jaccard[:, 1:] - jaccard[:, :-1]], dim=1)
    per_class = (errors_sorted * grad.detach()).sum(1)
    return per_class[present].mean()


def segmentation_loss(logits: torch.Tensor, labels: torch.Tensor, weights: torch.Tensor,
                      kind: str = "ce") -> torch.Tensor:
    """The training loss of one batch: class-weighted cross-entropy, plus Lovász-softmax for ``ce+lovasz``."""
    if kind not in LOSSES:
        raise ValueError(f"unknown loss {kind!r}; choose from {', '.join(LOSSES)}")
    loss = F.cross_entropy(logits, labels, weight=weights)
    if kind == "ce+lovasz":
        loss = loss + lovasz_softmax(torch.softmax(logits.float(), dim=1), labels)
    return loss


def describe(kind: str) -> str:
    """One line for the model card."""
    ce = "class-weighted cross-entropy (inverse sqrt frequency)"
    text = ce if kind == "ce" else f"{ce} + Lovász-softmax (batch-level, classes present)"
    return f"{text}, mean of working and HD scales"
