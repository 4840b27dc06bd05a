"""Monitors on any label set and network: CH beyond 16 classes, softmax scores
normalised by the network's class count, MC dropout refused at build in user terms, the shipped scores kept."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from el.base.decision import Candidate
from el.classes.labels import UAVID, LabelClass, LabelSet, load_label_set
from el.monitors import build_monitor
from el.monitors.base import CandidateContext
from el.monitors.capabilities import MonitorSupportError, model_kind
from el.monitors.hierarchy import LCA_TABLE_MAX_CLASSES, default_hierarchy
from el.monitors.learned import load_learned_model
from el.segmentation.class_map import MappedModel
from el.segmentation.inference import Segmenter

SD = load_label_set("semantic_drone")  # 23 classes
SIX = LabelSet("six", (
    LabelClass(0, "grass", (0, 160, 0), False, 0.0), LabelClass(1, "dirt", (130, 76, 0), False, 1.0),
    LabelClass(2, "road", (128, 64, 128), True, None), LabelClass(3, "water", (0, 0, 160), True, None),
    LabelClass(4, "roof", (70, 70, 70), True, None), LabelClass(5, "shrubs", (0, 90, 0), False, 2.0),
))
# a 6-class network seen in semantic_drone, one-to-one onto six of its safe classes (so its scores are uncertainty)
NET6 = LabelSet("net6", tuple(LabelClass(i, n, (i, 9, 9), i == 5, None if i == 5 else 0.0)
                              for i, n in enumerate(("grass", "dirt", "gravel", "rocks", "shrubs", "trees"))))
TO_SD = {"grass": "grass", "dirt": "dirt", "gravel": "gravel", "rocks": "rocks", "shrubs": "vegetation",
         "trees": "tree"}
UNREACHED = [n for n in SD.names if n not in TO_SD.values()]


def softmax(logits: np.ndarray, axis: int) -> np.ndarray:
    e = np.exp(logits - logits.max(axis=axis, keepdims=True))
    return (e / e.sum(axis=axis, keepdims=True)).astype(np.float32)


def random_probs(labels: LabelSet, shape: tuple[int, ...], seed: int) -> np.ndarray:
    return softmax(np.random.default_rng(seed).normal(0, 2.0, (labels.num_classes, *shape)), 0)


def disc(h: int, w: int) -> np.ndarray:
    yy, xx = np.mgrid[:h, :w]
    return (yy - h / 2) ** 2 + (xx - w / 2) ** 2 <= (min(h, w) / 2.5) ** 2


# -- CH on any class count --------------------------------------------------------------------------------
@pytest.mark.parametrize("labels", [SD, SIX], ids=["semantic_drone-23", "six"])
@pytest.mark.parametrize("spec", ["lhd+ch:tau=0.25", "lhd+ch:tau=0.1,threshold=0.5"])
def test_ch_builds_and_scores_on_any_label_set(labels, spec):
    monitor = build_monitor(spec, labels=labels)
    probs, mask = random_probs(labels, (40, 50), seed=1), disc(40, 50)
    verdict = monitor.check_scores(probs, mask)
    assert math.isfinite(verdict.score) and -1.0 <= verdict.score <= 1.0 and verdict.name == spec
    assert monitor.hierarchy.labels == labels and monitor.hierarchy.nodes[-3:] == ("any", "safe", "unsafe")
    mcd = build_monitor("lhd+ch+mcd:n=4,rho=0.9,tau=0.25", labels=labels)
    samples = np.stack([random_probs(labels, (40, 50), seed=s) for s in range(4)])
    assert math.isfinite(mcd.check_scores(samples, mask).score)


def brute_lca(h, classes: list[int]) -> int:
    """The deepest node whose subtree holds every class of ``classes`` (the root for none), by walking up."""
    if not classes:
        return h.root
    def up(k):
        path = [k]
        while h.parents[path[-1]] != -1:
            path.append(h.parents[path[-1]])
        return path
    common = set(up(classes[0])).intersection(*(set(up(k)) for k in classes[1:]))
    return next(a for a in up(classes[0]) if a in common)


def test_the_lca_without_a_table_is_the_lca():
    h = default_hierarchy(SD)
    assert SD.num_classes > LCA_TABLE_MAX_CLASSES and h.lca_table is None
    probs = random_probs(SD, (30, 30), seed=2)
    got = h.label(probs, 0.1)
    above = probs > 0.1
    for y, x in [(0, 0), (3, 7), (12, 29), (29, 5)] + [(i, i) for i in range(30)]:
        assert got[y, x] == brute_lca(h, [int(k) for k in np.flatnonzero(above[:, y, x])])
    # with a table (UAVid) both ways agree on every pixel, including pixels with no class above tau
    u = default_hierarchy(UAVID)
    p = random_probs(UAVID, (60, 60), seed=3)
    for tau in (0.05, 0.25, 0.9):
        np.testing.assert_array_equal(u._label_by_masks(p > tau), u.label(p, tau))


def test_the_lca_of_more_than_64_classes():
    many = LabelSet("many", tuple(LabelClass(i, f"c{i}", (i, i, 7), i % 3 == 0, None if i % 3 == 0 else 1.0)
                                  for i in range(70)))
    h = build_monitor("lhd+ch:tau=0.02", labels=many).hierarchy
    probs = random_probs(many, (12, 12), seed=5)
    got, above = h.label(probs, 0.02), probs > 0.02
    for y, x in np.ndindex(12, 12):
        assert got[y, x] == brute_lca(h, [int(k) for k in np.flatnonzero(above[:, y, x])])
    assert h.label(np.zeros((70, 2, 2)), 0.5).tolist() == [[h.root] * 2] * 2


def test_a_declared_hierarchy_is_used_and_a_class_named_like_an_inner_node_is_kept_apart():
    declared = LabelSet.from_dict({**SIX.to_dict(), "hierarchy": {"root": "all", "children": {
        "all": ["soft", "hard"], "soft": ["grass", "shrubs", "water"], "hard": ["dirt", "road", "roof"]}}})
    h = build_monitor("lhd+ch:tau=0.25", labels=declared).hierarchy
    assert h.nodes[6:] == ("all", "soft", "hard") and set(h.rejected_names) == {"all", "soft", "hard", "road",
                                                                                "water", "roof"}
    odd = LabelSet("odd", (LabelClass(0, "any", (1, 1, 1), False, 0.0), LabelClass(1, "unsafe", (2, 2, 2), True, None)))
    assert default_hierarchy(odd).nodes == ("any", "unsafe", "any_node", "safe", "unsafe_node")


# -- softmax scores normalised by the network's class count -------------------------------------------------
class Net6:
    """A 6-class network (its own softmax), deterministic per patch."""

    labels = NET6
    weights_sha256 = None

    def predict_frame(self, rgb):
        return random_probs(NET6, rgb.shape[:2], seed=0)

    def predict_patch(self, rgb):
        return random_probs(NET6, rgb.shape[:2], seed=int(rgb.sum()) % 997)


def own_uncertainties(p: np.ndarray) -> dict[str, np.ndarray]:
    """The network's own per-pixel uncertainties over its 6 classes, normalised for 6 classes."""
    p = p.astype(np.float64)
    c = p.shape[0]
    q = p / p.sum(axis=0)  # the float32 softmax sums to 1 within 1e-7: entropy and energy read it renormalised
    renyi = 2.0 * np.log((q ** 0.5).sum(axis=0))
    return {"msp": (1 - p.max(axis=0)) / (1 - 1 / c), "entropy": -(q * np.log(q)).sum(axis=0) / math.log(c),
            "energy": renyi / math.log(c)}


@pytest.mark.parametrize("kind", ["msp", "entropy", "energy"])
def test_softmax_scores_normalise_by_the_network_classes_of_a_mapped_map(kind):
    mapped = MappedModel(Net6(), TO_SD, SD, unreachable=UNREACHED)
    rgb = np.random.default_rng(4).integers(0, 256, (36, 44, 3), dtype=np.uint8)
    mask = disc(36, 44)
    own = Net6().predict_patch(rgb)  # (6, h, w)
    seen = mapped.predict_patch(rgb)  # (23, h, w): the same mass on six planes, 17 planes of 0
    assert seen.shape[0] == 23 and np.count_nonzero(seen.reshape(23, -1).any(axis=1)) == 6
    want = float(own_uncertainties(own)[kind][mask].max())
    given = build_monitor(kind, labels=SD, network_classes=6)
    derived = build_monitor(kind, labels=SD, model=mapped)  # the class map's network: 6 classes
    for monitor in (given, derived):
        assert monitor.network_classes == 6
        assert monitor.score(seen, mask) == pytest.approx(want, rel=1e-9, abs=1e-12)
    label_count = build_monitor(kind, labels=SD).score(seen, mask)  # the old normalisation, by log 23 for entropy
    assert label_count < want


def test_network_classes_must_be_a_class_count():
    for bad in (1, 0, True, 2.5, "6"):
        with pytest.raises(ValueError, match="network_classes"):
            build_monitor("entropy", labels=SD, network_classes=bad)
    assert build_monitor("lhd", labels=SD, network_classes=6).name == "lhd"  # the paper's scores read no count
    assert build_monitor("learned", labels=UAVID, network_classes=8).name == "learned"


# -- MC dropout needs a torch network with dropout layers ---------------------------------------------------
class NoDropout(nn.Module):
    def __init__(self, classes: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(3, classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


class WithDropout(NoDropout):
    def __init__(self, classes: int) -> None:
        super().__init__(classes)
        self.drop = nn.Dropout2d(0.5)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.drop(self.conv(x))


def test_mcd_is_refused_at_build_on_a_model_without_dropout():
    spec = "lhd+mcd:n=5,rho=0.9"
    mapped = MappedModel(Net6(), TO_SD, SD, unreachable=UNREACHED)
    with pytest.raises(MonitorSupportError, match=r"monitor 'lhd\+mcd:n=5,rho=0.9' needs MC dropout: a torch "
                                                  r"network with dropout layers") as err:
        build_monitor(spec, labels=SD, model=mapped)
    message = str(err.value)
    assert "class-mapped network" in message and "Net6" in message and "MappedModel" not in message
    assert "\n" not in message and isinstance(err.value, ValueError)
    plain = Segmenter(NoDropout(8), labels=UAVID, working_width=32)
    with pytest.raises(MonitorSupportError, match="the segmentation model is a torch network without dropout layers"):
        build_monitor("lhd+ch+mcd:n=5,rho=0.9,tau=0.25", labels=UAVID, model=plain)
    torch_mapped = MappedModel(Segmenter(NoDropout(8), labels=UAVID, working_width=32),
                               {n: n for n in UAVID.names}, UAVID)
    with pytest.raises(MonitorSupportError, match="class-mapped network .* over a torch network without dropout"):
        build_monitor(spec, labels=UAVID, model=torch_mapped)
    onnx_like = type("OnnxModel", (), {"labels": UAVID, "path": "net.onnx"})()
    assert model_kind(onnx_like).startswith("an ONNX network")
    with pytest.raises(MonitorSupportError, match=r"is an ONNX network, which runs without dropout \(net.onnx\)"):
        build_monitor(spec, labels=UAVID, model=onnx_like)
    dropout = Segmenter(WithDropout(8), labels=UAVID, working_width=32)
    assert build_monitor(spec, labels=UAVID, model=dropout).name == spec
    assert build_monitor("lhd", labels=SD, model=mapped).name == "lhd"  # no MC dropout needed: nothing to refuse


# -- the shipped system: the same scores as before ------------------------------------------------------------
class FakeUavidSegmenter:
    """Seeded softmax maps over UAVid's 8 classes; ``bias`` is added to the safe classes' logits."""

    labels = UAVID

    def __init__(self, bias: float) -> None:
        self.bias = bias
        self.weights_sha256 = load_learned_model(labels=UAVID).network_sha256  # the learned model accepts it

    def _probs(self, shape: tuple[int, ...], seed: int) -> np.ndarray:
        logits = np.random.default_rng(seed).normal(0, 2.0, size=shape).astype(np.float32)
        b = np.zeros(8, np.float32)
        b[list(UAVID.safe_ids)] = self.bias
        logits += b.reshape(8, 1, 1)
        e = np.exp(logits - logits.max(axis=-3, keepdims=True))
        return (e / e.sum(axis=-3, keepdims=True)).astype(np.float32)

    def predict_patch(self, rgb):
        return self._probs((8, *rgb.shape[:2]), int(rgb.sum()) % 1000)

    def predict_frame(self, rgb):
        return self._probs((8, 36, 64), 7)

    def mc_dropout(self, rgb, n, keep, seed):
        return self._probs((n, 8, *rgb.shape[:2]), seed + int(rgb.sum()) % 1000)


# Obtained BEFORE monitors served any label set, by running exactly test_shipped_uavid_scores_are_unchanged's loop
# on the unchanged code (build_monitor(spec, labels=UAVID), check(...)), printing float(score).hex(), accepted
# and reason: the shipped UAVid monitors must keep bit-identical scores and verdicts.
SHIPPED_REFERENCE = {
    (0.0, 'lhd'): [
        ('0x1.13716aefcc26ep-1', False,
         'forbidden classes in disc: building (51 px), static_car (46 px), moving_car (37 px), road '
         '(36 px)'),
        ('0x1.e4129e4129e41p-2', False,
         'forbidden classes in disc: static_car (18 px), moving_car (14 px), road (11 px), building '
         '(9 px)'),
    ],
    (0.0, 'lhd+ch:tau=0.25'): [
        ('0x1.52a2067b23a54p-1', False,
         'forbidden classes in disc: building (51 px), static_car (46 px), moving_car (37 px), road '
         '(36 px); rejected hierarchy labels in disc (tau=0.25): any (72 px), unsafe (24 px)'),
        ('0x1.2094f2094f209p-1', False,
         'forbidden classes in disc: static_car (18 px), moving_car (14 px), road (11 px), building '
         '(9 px); rejected hierarchy labels in disc (tau=0.25): any (18 px), unsafe (10 px)'),
    ],
    (0.0, 'lhd+ch:tau=0.1'): [
        ('0x1.b23a5440cf647p-1', False,
         'forbidden classes in disc: building (51 px), static_car (46 px), moving_car (37 px), road '
         '(36 px); rejected hierarchy labels in disc (tau=0.1): any (207 px), unsafe (37 px)'),
        ('0x1.86fb586fb5870p-1', False,
         'forbidden classes in disc: static_car (18 px), moving_car (14 px), road (11 px), building '
         '(9 px); rejected hierarchy labels in disc (tau=0.1): any (61 px), unsafe (18 px)'),
    ],
    (0.0, 'msp'): [
        ('0x1.89b8b577e6137p+0', False,
         'forbidden top class on 170 of 316 px; score 1.53797 > threshold 1'),
        ('0x1.7904a7904a790p+0', False,
         'forbidden top class on 52 of 110 px; score 1.47273 > threshold 1'),
    ],
    (0.0, 'entropy'): [
        ('0x1.89b8b577e6137p+0', False,
         'forbidden top class on 170 of 316 px; score 1.53797 > threshold 1'),
        ('0x1.7904a7904a790p+0', False,
         'forbidden top class on 52 of 110 px; score 1.47273 > threshold 1'),
    ],
    (0.0, 'energy'): [
        ('0x1.89b8b577e6137p+0', False,
         'forbidden top class on 170 of 316 px; score 1.53797 > threshold 1'),
        ('0x1.7904a7904a790p+0', False,
         'forbidden top class on 52 of 110 px; score 1.47273 > threshold 1'),
    ],
    (0.0, 'lhd+mcd:n=5,rho=0.9'): [
        ('0x1.0b577e613716bp-1', False,
         'forbidden classes in disc: building (46 px), static_car (45 px), moving_car (42 px), road '
         '(32 px)'),
        ('0x1.c8253c8253c82p-2', False,
         'forbidden classes in disc: building (14 px), road (14 px), moving_car (12 px), static_car '
         '(9 px)'),
    ],
    (0.0, 'lhd+ch+mcd:n=5,rho=0.9,tau=0.25'): [
        ('0x1.0000000000000p+0', False,
         'forbidden classes in disc: building (46 px), static_car (45 px), moving_car (42 px), road '
         '(32 px); rejected hierarchy labels in disc (tau=0.25): any (316 px)'),
        ('0x1.0000000000000p+0', False,
         'forbidden classes in disc: building (14 px), road (14 px), moving_car (12 px), static_car '
         '(9 px); rejected hierarchy labels in disc (tau=0.25): any (110 px)'),
    ],
    (0.0, 'learned'): [
        ('0x1.fe940f249b3a9p-1', False,
         'P(unsafe) 0.9972 > threshold 0.1841'),
        ('0x1.fffffa84f5f22p-1', False,
         'P(unsafe) 1.0000 > threshold 0.1841'),
    ],
    (5.0, 'lhd'): [
        ('-0x1.1a6f300000000p-6', True,
         'no forbidden pixel in disc (316 px)'),
        ('-0x1.0bda880000000p-2', True,
         'no forbidden pixel in disc (110 px)'),
    ],
    (5.0, 'lhd+ch:tau=0.25'): [
        ('0x1.9ec8e951033d9p-8', False,
         'rejected hierarchy labels in disc (tau=0.25): any (2 px)'),
        ('-0x1.0bda880000000p-2', True,
         'no forbidden, unsafe or uncertain pixel in disc (110 px)'),
    ],
    (5.0, 'lhd+ch:tau=0.1'): [
        ('0x1.3716aefcc26e3p-5', False,
         'rejected hierarchy labels in disc (tau=0.1): any (12 px)'),
        ('0x1.bed61bed61bedp-5', False,
         'rejected hierarchy labels in disc (tau=0.1): any (6 px)'),
    ],
    (5.0, 'msp'): [
        ('0x1.b1fdd24924925p-1', True,
         'largest msp uncertainty 0.8476 (316 px); score 0.84764 <= threshold 1'),
        ('0x1.7e8a280000000p-1', True,
         'largest msp uncertainty 0.7471 (110 px); score 0.747148 <= threshold 1'),
    ],
    (5.0, 'entropy'): [
        ('0x1.9f969362b0976p-1', True,
         'largest entropy uncertainty 0.8117 (316 px); score 0.811696 <= threshold 1'),
        ('0x1.875987963fb33p-1', True,
         'largest entropy uncertainty 0.7644 (110 px); score 0.764355 <= threshold 1'),
    ],
    (5.0, 'energy'): [
        ('0x1.bbb245133b571p-1', True,
         'largest energy uncertainty 0.8666 (316 px); score 0.866594 <= threshold 1'),
        ('0x1.b0b0f161eb850p-1', True,
         'largest energy uncertainty 0.8451 (110 px); score 0.8451 <= threshold 1'),
    ],
    (5.0, 'lhd+mcd:n=5,rho=0.9'): [
        ('0x1.9ec8e951033d9p-9', False,
         'forbidden class in disc: road (1 px)'),
        ('-0x1.dfba880000000p-3', True,
         'no forbidden pixel in disc (110 px)'),
    ],
    (5.0, 'lhd+ch+mcd:n=5,rho=0.9,tau=0.25'): [
        ('0x1.9ec8e951033d9p-4', False,
         'forbidden class in disc: road (1 px); rejected hierarchy labels in disc (tau=0.25): any (3'
         '2 px)'),
        ('0x1.745d1745d1746p-4', False,
         'rejected hierarchy labels in disc (tau=0.25): any (10 px)'),
    ],
    (5.0, 'learned'): [
        ('0x1.03153d1a284acp-1', False,
         'P(unsafe) 0.5060 > threshold 0.1841'),
        ('0x1.3fd10bb5be0c1p-1', False,
         'P(unsafe) 0.6246 > threshold 0.1841'),
    ],
}


def test_shipped_uavid_scores_are_unchanged():
    hd = np.random.default_rng(20240601).integers(0, 256, size=(288, 512, 3), dtype=np.uint8)
    cands = [Candidate(0, 100.0, 120.0, 10.0, 0.5, 0.5, 0.0), Candidate(1, 300.5, 200.25, 6.0, 1.0, 1.0, 0.0)]
    for (bias, spec), want in SHIPPED_REFERENCE.items():
        seg = FakeUavidSegmenter(bias)
        frame = seg.predict_frame(hd)
        monitor = build_monitor(spec, labels=UAVID)
        for k, (cand, (score, accepted, reason)) in enumerate(zip(cands, want, strict=True)):
            v = monitor.check(hd, cand, seg, seed=3 + k, context=CandidateContext(cand, frame, (512, 288)))
            assert (float(v.score).hex(), v.accepted, v.reason) == (score, accepted, reason), (bias, spec, k)
