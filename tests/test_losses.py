"""The training losses: Lovász-softmax equals 1 - IoU on hard predictions, and it trains."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from assurance.fitting.network.evaluation import confusion, iou_from_confusion
from assurance.fitting.network.losses import LOSSES, lovasz_softmax, segmentation_loss


def _one_hot_probs(pred: torch.Tensor, classes: int) -> torch.Tensor:
    return torch.nn.functional.one_hot(pred, classes).permute(0, 3, 1, 2).float()


def test_lovasz_is_one_minus_iou_on_one_hot_predictions() -> None:
    rng = np.random.default_rng(3)
    labels = torch.from_numpy(rng.integers(0, 4, (2, 9, 7)))
    pred = torch.where(torch.from_numpy(rng.random((2, 9, 7)) < 0.7), labels,
                       torch.from_numpy(rng.integers(0, 4, (2, 9, 7))))
    loss = lovasz_softmax(_one_hot_probs(pred, 4), labels)
    iou = iou_from_confusion(confusion(labels.numpy(), pred.numpy(), 4))
    assert loss.item() == pytest.approx(1.0 - float(np.mean(iou)), abs=1e-6)


def test_lovasz_is_zero_when_perfect_and_ignores_absent_classes() -> None:
    labels = torch.tensor([[[0, 0, 2], [2, 2, 0]]])
    assert lovasz_softmax(_one_hot_probs(labels, 5), labels).item() == pytest.approx(0.0)
    # class 1 is predicted but absent from the labels: it does not enter the mean
    pred = labels.clone()
    pred[0, 0, 0] = 1
    loss = lovasz_softmax(_one_hot_probs(pred, 5), labels).item()
    assert loss == pytest.approx(0.5 * ((1 - 2 / 3) + 0.0))


def test_lovasz_gradient_lowers_the_loss() -> None:
    torch.manual_seed(0)
    labels = torch.randint(0, 3, (1, 6, 6))
    logits = torch.zeros(1, 3, 6, 6, requires_grad=True)
    opt = torch.optim.SGD([logits], lr=20.0)
    first = None
    for _ in range(20):
        loss = lovasz_softmax(torch.softmax(logits, 1), labels)
        first = first if first is not None else loss.item()
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < 0.5 * first


def test_segmentation_loss_kinds() -> None:
    logits = torch.randn(2, 4, 5, 5)
    labels = torch.randint(0, 4, (2, 5, 5))
    weights = torch.ones(4)
    ce = segmentation_loss(logits, labels, weights, "ce")
    both = segmentation_loss(logits, labels, weights, "ce+lovasz")
    assert both.item() > ce.item()
    assert set(LOSSES) == {"ce", "ce+lovasz"}
    with pytest.raises(ValueError, match="unknown loss"):
        segmentation_loss(logits, labels, weights, "dice")
    with pytest.raises(ValueError, match="expected probs"):
        lovasz_softmax(logits, labels[0])


def test_the_command_line_offers_every_loss() -> None:
    import argparse

    from assurance.cli.train import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    action = next(a for a in parser._actions if a.dest == "loss")
    assert tuple(action.choices) == LOSSES and action.default == "ce"
