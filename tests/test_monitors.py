"""Runtime monitors (docs/architecture.md 3.6): LHD, CH, MCD, their names, patch geometry and fail-safe inputs."""

from __future__ import annotations

import doctest
import itertools
import math

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import el.monitors as mon
from el.base.decision import Candidate, Disc, MonitorVerdict
from el.classes.labels import CLASS_IDS, CLASS_NAMES, FORBIDDEN_LUT, NUM_CLASSES, UAVID, colors_to_ids, ids_to_colors
from el.monitors import (
    DEMO_GRID,
    PAPER_GRID,
    CHMonitor,
    ClassHierarchy,
    LHDMonitor,
    MonitorSpec,
    PatchSegmenter,
    build_monitor,
    default_hierarchy,
    extract_patch,
    mcd_score,
    parse_monitor_spec,
)
from el.monitors.lhd import take_disc

SAFE_NAMES = {"clutter", "tree", "low_vegetation", "human"}
UNSAFE_NAMES = {"building", "road", "static_car", "moving_car"}
REJECTED_LABELS = {"any", "unsafe"} | UNSAFE_NAMES


# -- test segmenters ----------------------------------------------------------------------------
def one_hot_scores(ids: np.ndarray, top: float = 0.93) -> np.ndarray:
    """Softmax-like scores (8, h, w): ``top`` on the class, the rest shared by the others."""
    rest = (1.0 - top) / (NUM_CLASSES - 1)
    scores = np.full((NUM_CLASSES, *ids.shape), rest, dtype=np.float32)
    np.put_along_axis(scores, ids[None].astype(np.int64), top, axis=0)
    return scores


class ColourSegmenter:
    """A perfect segmenter for label-colour images: it sees exactly what is in the patch."""

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        return one_hot_scores(colors_to_ids(rgb_patch))

    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        base = self.predict_patch(rgb_patch)
        noise = rng.normal(0.0, 0.02 * (1 - keep_prob), size=(n, *base.shape)).astype(np.float32)
        return np.clip(base[None] + noise, 0.0, 1.0)


class TinyTorchSegmenter:
    """Conv2d -> ReLU -> Dropout2d -> Conv2d(1x1) over 8 classes, implementing ``PatchSegmenter``.

    MC dropout runs the n passes as one batch; the channel masks are drawn sample after sample
    from a generator seeded with ``seed``, so the samples are prefix-consistent.
    """

    def __init__(self, seed: int = 0, channels: int = 6):
        g = torch.Generator().manual_seed(seed)
        self.conv1 = torch.nn.Conv2d(3, channels, 3, padding=1)
        self.drop = torch.nn.Dropout2d(0.5)
        self.conv2 = torch.nn.Conv2d(channels, NUM_CLASSES, 1)
        self.net = torch.nn.Sequential(self.conv1, torch.nn.ReLU(), self.drop, self.conv2).eval()
        with torch.no_grad():
            for p in self.net.parameters():
                p.copy_(torch.randn(p.shape, generator=g))
        self.channels = channels

    @staticmethod
    def _input(rgb_patch: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(rgb_patch).permute(2, 0, 1)[None].float() / 255.0

    @torch.no_grad()
    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        return torch.softmax(self.net(self._input(rgb_patch)), dim=1)[0].numpy()

    @torch.no_grad()
    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int) -> np.ndarray:
        feats = torch.relu(self.conv1(self._input(rgb_patch)))  # (1, C, h, w), shared by the batch
        keep = np.random.default_rng(seed).random((n, self.channels)) < keep_prob
        masks = torch.from_numpy(keep.astype(np.float32) / keep_prob)[:, :, None, None]
        return torch.softmax(self.conv2(feats * masks), dim=1).numpy()


def labels_image(h: int, w: int, name: str = "low_vegetation") -> np.ndarray:
    return np.full((h, w), CLASS_IDS[name], dtype=np.uint8)


# -- the class hierarchy --------------------------------------------------------------------------
def scores_above(names: list[str], tau: float = 0.25) -> np.ndarray:
    """A score vector (8, 1) with the given classes above tau and every other one below it."""
    s = np.full((NUM_CLASSES, 1), tau / 4, dtype=np.float32)
    for name in names:
        s[CLASS_IDS[name]] = tau + 0.1
    return s


@pytest.mark.requirements("EL-R04")
@pytest.mark.parametrize(
    ("above", "label"),
    [
        (["tree", "human"], "safe"),
        (["road", "tree"], "any"),
        ([], "any"),
        (["tree"], "tree"),
        (["road"], "road"),
        (["building", "road"], "unsafe"),
        (["static_car", "moving_car", "building"], "unsafe"),
        (["clutter", "low_vegetation", "tree", "human"], "safe"),
        (["human", "moving_car"], "any"),
    ],
)
def test_hierarchy_labels_hand_made_vectors(above, label):
    h = default_hierarchy(labels=UAVID)
    for tau in (0.25, 0.125):
        assert h.names(h.label(scores_above(above, tau), tau))[0] == label


def test_hierarchy_label_is_strictly_above_tau():
    h = default_hierarchy(labels=UAVID)
    s = np.full((NUM_CLASSES, 1), 0.0, dtype=np.float32)
    s[CLASS_IDS["tree"]] = 0.25
    s[CLASS_IDS["road"]] = 0.3
    assert h.names(h.label(s, 0.25))[0] == "road"  # tree at exactly tau does not count


def test_hierarchy_file_matches_design_and_brute_force_lca():
    h = default_hierarchy(labels=UAVID)
    assert h.nodes[:NUM_CLASSES] == CLASS_NAMES
    assert set(h.rejected_names) == REJECTED_LABELS
    assert h.nodes[h.root] == "any"
    for m in range(2**NUM_CLASSES):
        names = {CLASS_NAMES[k] for k in range(NUM_CLASSES) if m >> k & 1}
        if len(names) == 1:
            want = names.pop()
        elif names and names <= SAFE_NAMES:
            want = "safe"
        elif names and names <= UNSAFE_NAMES:
            want = "unsafe"
        else:
            want = "any"
        assert h.nodes[h.lca_table[m]] == want, names


def test_hierarchy_from_yaml_and_bad_trees(tmp_path):
    good = tmp_path / "h.yaml"
    good.write_text(
        "root: any\nchildren:\n  any: [vehicles, rest]\n  vehicles: [static_car, moving_car]\n"
        "  rest: [clutter, building, road, tree, low_vegetation, human]\n"
    )
    h = ClassHierarchy.from_yaml(good, labels=UAVID)
    assert h.names(h.label(scores_above(["static_car", "moving_car"]), 0.25))[0] == "vehicles"
    assert "rest" in h.rejected_names  # it holds building and road
    bad_trees = {
        "missing class": "root: any\nchildren:\n  any: [clutter, building]\n",
        "two parents": "root: any\nchildren:\n  any: [safe, unsafe, tree]\n  safe: [clutter, tree, "
        "low_vegetation, human]\n  unsafe: [building, road, static_car, moving_car]\n",
        "not a tree": "just text\n",
    }
    for why, text in bad_trees.items():
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match="bad.yaml"):
            ClassHierarchy.from_yaml(path, labels=UAVID)
            pytest.fail(f"accepted a hierarchy with a fault: {why}")


# -- LHD ----------------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R04")
def test_lhd_accepts_all_safe_disc_and_rejects_one_forbidden_pixel():
    ids = np.array([[0, 4, 5, 6]] * 4, dtype=np.uint8)  # every safe class
    mask = np.ones(ids.shape, bool)
    ok, reason = LHDMonitor(labels=UAVID).decide(one_hot_scores(ids), mask)
    assert ok and "no forbidden pixel" in reason
    ids[2, 1] = CLASS_IDS["road"]
    ok, reason = LHDMonitor(labels=UAVID).decide(one_hot_scores(ids), mask)
    assert not ok and reason == "forbidden class in disc: road (1 px)"
    mask[2, 1] = False  # the road pixel is outside the disc: only the disc counts
    ok, _ = LHDMonitor(labels=UAVID).decide(one_hot_scores(ids), mask)
    assert ok


def test_lhd_reason_counts_every_forbidden_class_and_ties_count_as_forbidden():
    ids = labels_image(6, 6)
    ids[0, :3] = CLASS_IDS["road"]
    ids[5, 5] = CLASS_IDS["moving_car"]
    scores = one_hot_scores(ids)
    ok, reason = LHDMonitor(labels=UAVID).decide(scores, np.ones(ids.shape, bool))
    assert not ok and reason == "forbidden classes in disc: road (3 px), moving_car (1 px)"
    tie = np.full((NUM_CLASSES, 1, 1), 0.125, np.float32)  # uniform: clutter ties with building
    ok, reason = LHDMonitor(labels=UAVID).decide(tie, np.ones((1, 1), bool))
    assert not ok and "building (1 px)" in reason


@pytest.mark.requirements("EL-R04")
def test_lhd_sees_a_car_too_small_for_the_working_resolution():
    """A 3x3 px car inside the disc vanishes at 1024x576 (nearest) but not in the HD patch."""
    hd_ids = labels_image(2160, 3840)
    hd_ids[1504:1507, 1504:1507] = CLASS_IDS["static_car"]  # between nearest samples
    hd = ids_to_colors(hd_ids)
    working = cv2.resize(hd_ids, (1024, 576), interpolation=cv2.INTER_NEAREST)
    assert not (working == CLASS_IDS["static_car"]).any()
    cand = Candidate(rank=0, x=1510.0, y=1512.0, radius_px=40.0, hazard=0.0, hazard_semantic=0.0,
                     hazard_distance=0.0)
    verdict = LHDMonitor(labels=UAVID).check(hd, cand, ColourSegmenter())
    assert isinstance(verdict, MonitorVerdict)
    assert verdict.name == "lhd" and not verdict.accepted
    assert verdict.reason == "forbidden class in disc: static_car (9 px)"
    moved = Disc(1610.0, 1512.0, 40.0)  # the same disc 100 px to the right: clear
    assert LHDMonitor(labels=UAVID).check(hd, moved, ColourSegmenter()).accepted
    # CH and MCD see it as well.
    for spec in DEMO_GRID:
        assert not build_monitor(spec, labels=UAVID).check(hd, cand, ColourSegmenter(), seed=1).accepted, spec


# -- CH -----------------------------------------------------------------------------------------
def brute_force_ch(scores: np.ndarray, mask: np.ndarray, tau: float) -> bool:
    """Accepted by LHD+CH, pixel by pixel from the words of docs/architecture.md section 3.6."""
    for r, c in zip(*np.nonzero(mask), strict=True):
        s = scores[:, r, c]
        if FORBIDDEN_LUT[np.flatnonzero(s == s.max())].any():
            return False
        names = {CLASS_NAMES[k] for k in np.flatnonzero(s > tau)}
        if len(names) == 1:
            label = names.pop()
        elif names and names <= SAFE_NAMES:
            label = "safe"
        elif names and names <= UNSAFE_NAMES:
            label = "unsafe"
        else:
            label = "any"
        if label in REJECTED_LABELS:
            return False
    return bool(mask.any())


@st.composite
def softmax_patches(draw, *, h: int = 3, w: int = 3):
    logits = draw(hnp.arrays(np.float32, (NUM_CLASSES, h, w), elements=st.floats(-4, 4, width=32)))
    e = np.exp(logits - logits.max(axis=0))
    mask = draw(hnp.arrays(np.bool_, (h, w)))
    return (e / e.sum(axis=0)).astype(np.float32), mask


@pytest.mark.requirements("EL-R04")
@settings(max_examples=150, deadline=None)
@given(patch=softmax_patches(), tau=st.sampled_from([0.25, 0.125]))
def test_ch_rejects_whenever_a_disc_pixel_is_unsafe_or_uncertain(patch, tau):
    scores, mask = patch
    monitor = CHMonitor(tau=tau, labels=UAVID)
    ok, _ = monitor.decide(scores, mask)
    assert ok == brute_force_ch(scores, mask, tau)
    labels = default_hierarchy(labels=UAVID).names(default_hierarchy(labels=UAVID).label(scores, tau))
    if any(lab in REJECTED_LABELS for lab in labels[mask]):
        assert not ok
    if not LHDMonitor(labels=UAVID).decide(scores, mask)[0]:
        assert not ok  # CH is on top of LHD


@pytest.mark.requirements("EL-R04")
def test_ch_reason_names_uncertain_pixels():
    scores = one_hot_scores(labels_image(4, 4))
    scores[:, 1, 1] = scores_above(["road", "tree"])[:, 0]  # road ~ tree: labelled any
    scores[:, 2, 2] = scores_above(["tree", "human"])[:, 0]  # safe: fine
    mask = np.ones((4, 4), bool)
    ok, reason = CHMonitor(tau=0.25, labels=UAVID).decide(scores, mask)
    assert not ok and "any (1 px)" in reason
    mask[1, 1] = False
    ok, reason = CHMonitor(tau=0.25, labels=UAVID).decide(scores, mask)
    assert ok and "15 px" in reason
    flat = np.full((NUM_CLASSES, 4, 4), 1 / NUM_CLASSES, np.float32)  # nothing above tau: any
    flat[CLASS_IDS["tree"]] += 1e-3
    ok, reason = CHMonitor(tau=0.25, labels=UAVID).decide(flat, mask)
    assert not ok and "any (15 px)" in reason


# -- MCD ----------------------------------------------------------------------------------------
def test_mcd_score_is_mean_plus_three_std():
    samples = np.zeros((2, NUM_CLASSES, 1, 1), np.float32)
    samples[:, 5, 0, 0] = (0.2, 0.4)
    np.testing.assert_allclose(mcd_score(samples)[5, 0, 0], 0.3 + 3 * 0.1, rtol=1e-6)
    many = np.random.default_rng(0).random((7, NUM_CLASSES, 5, 4), dtype=np.float32)
    np.testing.assert_allclose(mcd_score(many), many.mean(0) + 3 * many.std(0), rtol=1e-5, atol=1e-6)


@pytest.mark.requirements("EL-R04")
def test_mcd_rejects_on_the_score_where_the_mean_looks_safe():
    samples = np.zeros((4, NUM_CLASSES, 1, 1), np.float32)
    samples[:, CLASS_IDS["low_vegetation"]] = 0.6
    samples[:, CLASS_IDS["road"], 0, 0] = (0.1, 0.5, 0.1, 0.5)  # mean 0.3, std 0.2: S = 0.9
    mask = np.ones((1, 1), bool)
    assert LHDMonitor(labels=UAVID).decide(samples.mean(axis=0), mask)[0]
    lhd_mcd = build_monitor("lhd+mcd:n=4,rho=0.9", labels=UAVID)
    ok, reason = lhd_mcd.decide(samples, mask)
    assert not ok and "road (1 px)" in reason
    ok, _ = build_monitor("lhd+ch+mcd:tau=0.25,n=4,rho=0.9", labels=UAVID).decide(samples, mask)
    assert not ok  # road and low vegetation both above tau: any


def test_mcd_is_reproducible_and_n10_is_the_prefix_of_n30():
    seg = TinyTorchSegmenter()
    rgb = np.random.default_rng(0).integers(0, 256, (24, 20, 3), dtype=np.uint8)
    s30 = seg.mc_dropout(rgb, 30, 0.5, seed=7)
    assert s30.shape == (30, NUM_CLASSES, 24, 20) and s30.dtype == np.float32
    np.testing.assert_array_equal(seg.mc_dropout(rgb, 30, 0.5, seed=7), s30)
    np.testing.assert_array_equal(seg.mc_dropout(rgb, 10, 0.5, seed=7), s30[:10])
    assert not np.array_equal(seg.mc_dropout(rgb, 10, 0.5, seed=8), s30[:10])

    hd = np.random.default_rng(1).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    disc = Disc(80.0, 70.0, 15.0)
    m10 = build_monitor("lhd+ch+mcd:tau=0.25,n=10,rho=0.5", labels=UAVID)
    a, b = m10.check(hd, disc, seg, seed=3), m10.check(hd, disc, seg, seed=3)
    assert (a.accepted, a.reason) == (b.accepted, b.reason)
    # A campaign draws 30 samples once; the n=10 configuration uses their prefix.
    patch = m10.patch(hd, disc)
    shared = seg.mc_dropout(patch.rgb, 30, 0.5, seed=3)
    own = m10.features(patch.rgb, seg, seed=3)
    np.testing.assert_array_equal(own, shared[:10])
    assert m10.decide(shared, patch.disc_mask) == m10.decide(own, patch.disc_mask) == (a.accepted, a.reason)
    assert m10.feature_key == build_monitor("lhd+mcd:n=30,rho=0.5", labels=UAVID).feature_key
    with pytest.raises(ValueError, match="10 MC samples needed"):
        m10.decide(shared[:5], patch.disc_mask)


# -- names and specs ----------------------------------------------------------------------------
def test_paper_grid_has_the_21_configurations_in_order():
    assert len(PAPER_GRID) == len(set(PAPER_GRID)) == 21
    kinds = [parse_monitor_spec(s).kind for s in PAPER_GRID]
    assert kinds == ["lhd"] + ["lhd+ch"] * 2 + ["lhd+mcd"] * 6 + ["lhd+ch+mcd"] * 12
    assert PAPER_GRID[:4] == ("lhd", "lhd+ch:tau=0.25", "lhd+ch:tau=0.125", "lhd+mcd:n=10,rho=0.5")
    assert PAPER_GRID[-1] == "lhd+ch+mcd:tau=0.125,n=30,rho=0.9"
    grid = {(s.tau, s.n, s.rho) for s in map(parse_monitor_spec, PAPER_GRID)}
    combos = itertools.product((None, 0.25, 0.125), (None, 10, 30), (None, 0.5, 0.75, 0.9))
    want = {(t, n, r) for t, n, r in combos if (n is None) == (r is None)}
    assert grid == want
    assert set(DEMO_GRID) <= set(PAPER_GRID) and len(DEMO_GRID) == 4
    assert MonitorSpec.from_paper_row(-1, -1, -1).name == "lhd"
    assert MonitorSpec.from_paper_row(30, 0.125, 0.75).name == "lhd+ch+mcd:tau=0.125,n=30,rho=0.75"
    assert MonitorSpec.from_paper_row(10, -1, 0.9).name == "lhd+mcd:n=10,rho=0.9"


@pytest.mark.requirements("EL-R04")
def test_every_paper_spec_parses_round_trips_and_runs_on_a_torch_model():
    seg = TinyTorchSegmenter()
    assert isinstance(seg, PatchSegmenter)
    hd = np.random.default_rng(2).integers(0, 256, (90, 120, 3), dtype=np.uint8)
    cand = Candidate(rank=0, x=60.0, y=50.0, radius_px=9.0, hazard=0.1, hazard_semantic=0.1,
                     hazard_distance=0.0)
    for name in PAPER_GRID:
        spec = parse_monitor_spec(name)
        assert spec.name == name and parse_monitor_spec(spec.name) == spec and str(spec) == name
        monitor = build_monitor(name, labels=UAVID)
        assert monitor.name == name and monitor.spec == spec
        verdict = monitor.check(hd, cand, seg, seed=0)
        assert verdict.name == name and isinstance(verdict.accepted, bool) and verdict.reason
        assert 0 <= verdict.seconds < 10
        patch = monitor.patch(hd, cand)
        again = monitor.check_scores(monitor.features(patch.rgb, seg, seed=0), patch.disc_mask)
        assert (again.accepted, again.reason) == (verdict.accepted, verdict.reason)


def test_spec_parsing_is_lenient_on_layout_and_none_means_no_monitor():
    assert parse_monitor_spec(" LHD + CH : tau = 0.250 ").name == "lhd+ch:tau=0.25"
    assert parse_monitor_spec("lhd+mcd+ch:rho=0.9,n=10,tau=.25").name == "lhd+ch+mcd:tau=0.25,n=10,rho=0.9"
    assert parse_monitor_spec("none") is None and parse_monitor_spec("None") is None
    assert build_monitor("none", labels=UAVID) is None and build_monitor(None, labels=UAVID) is None
    assert mon.monitor_name("none") == "none" and mon.monitor_name("lhd") == "lhd"
    odd = MonitorSpec(tau=0.2, n=7, rho=1.0)  # calibration values off the paper's grid
    assert parse_monitor_spec(odd.name) == odd


@pytest.mark.parametrize(
    "text",
    ["", "lhd+", "ch", "mcd", "lhd+ch", "lhd+ch:", "lhd+ch:tau", "lhd+ch:tau=2", "lhd+ch:tau=nan",
     "lhd+ch:tau=0.25,tau=0.25", "lhd:tau=0.25", "lhd+mcd:n=10", "lhd+mcd:n=1,rho=0.5",
     "lhd+mcd:n=10.5,rho=0.5", "lhd+mcd:n=10,rho=0", "lhd+lhd", "lhd+ch+mcd:tau=0.25,n=10", "foo"],
)
def test_bad_specs_raise_with_the_valid_forms(text):
    with pytest.raises(ValueError) as err:
        parse_monitor_spec(text)
    msg = str(err.value)
    assert repr(text) in msg and "valid forms" in msg and "lhd+ch+mcd:tau=T,n=N,rho=R" in msg


def test_bad_spec_values_raise_when_built():
    for kwargs in ({"tau": 0.0}, {"tau": True}, {"n": 10}, {"n": 10, "rho": 1.5}, {"n": 1, "rho": 0.5}):
        with pytest.raises(ValueError):
            MonitorSpec(**kwargs)
    with pytest.raises(ValueError, match="margin"):
        build_monitor("lhd", margin=-0.1, labels=UAVID)
    with pytest.raises(ValueError, match="max_side"):
        build_monitor("lhd", max_side=4, labels=UAVID)


# -- fail safe ----------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_scores_raise(bad):
    scores = one_hot_scores(labels_image(4, 4))
    scores[3, 0, 0] = bad  # even outside the disc: the segmenter is faulty
    mask = np.zeros((4, 4), bool)
    mask[2:, 2:] = True
    for name in ("lhd", "lhd+ch:tau=0.25"):
        with pytest.raises(ValueError, match="non-finite scores"):
            build_monitor(name, labels=UAVID).check_scores(scores, mask)
    samples = np.repeat(one_hot_scores(labels_image(4, 4))[None], 10, axis=0)
    samples[9, 0, 1, 1] = bad
    with pytest.raises(ValueError, match="non-finite scores"):
        build_monitor("lhd+ch+mcd:tau=0.25,n=10,rho=0.9", labels=UAVID).check_scores(samples, mask)

    class Broken(ColourSegmenter):
        def predict_patch(self, rgb_patch):
            out = super().predict_patch(rgb_patch)
            out[0, 0, 0] = bad
            return out

    hd = ids_to_colors(labels_image(40, 40))
    with pytest.raises(ValueError, match="non-finite scores"):
        LHDMonitor(labels=UAVID).check(hd, Disc(20.0, 20.0, 5.0), Broken())


def test_wrong_shapes_and_types_raise():
    scores = one_hot_scores(labels_image(4, 4))
    mask = np.ones((4, 4), bool)
    m = LHDMonitor(labels=UAVID)
    with pytest.raises(ValueError, match="shape"):
        m.decide(scores[:, :3], mask)
    with pytest.raises(ValueError, match="shape"):
        m.decide(scores[:7], mask)
    with pytest.raises(ValueError, match="bool"):
        m.decide(scores, mask.astype(np.uint8))
    with pytest.raises(ValueError, match="floating"):
        m.decide(scores.astype(np.int64), mask)
    with pytest.raises(ValueError, match="4-D"):
        build_monitor("lhd+mcd:n=10,rho=0.9", labels=UAVID).decide(scores, mask)
    hd = ids_to_colors(labels_image(40, 40))
    with pytest.raises(ValueError, match="uint8"):
        m.check(hd.astype(np.float32), Disc(20.0, 20.0, 5.0), ColourSegmenter())
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        m.check(hd[..., 0], Disc(20.0, 20.0, 5.0), ColourSegmenter())
    for disc in (Disc(20.0, 20.0, 0.0), Disc(math.nan, 20.0, 5.0), Disc(20.0, 20.0, math.inf)):
        with pytest.raises(ValueError):
            m.check(hd, disc, ColourSegmenter())
    with pytest.raises(ValueError, match="Disc or Candidate"):
        m.check(hd, (20, 20, 5), ColourSegmenter())

    class WrongSize(ColourSegmenter):
        def predict_patch(self, rgb_patch):
            return super().predict_patch(rgb_patch)[:, 1:]

    with pytest.raises(ValueError, match="shape"):
        m.check(hd, Disc(20.0, 20.0, 5.0), WrongSize())


def test_empty_disc_is_rejected():
    scores = one_hot_scores(labels_image(3, 3))
    for name in ("lhd", "lhd+ch:tau=0.25"):
        ok, reason = build_monitor(name, labels=UAVID).decide(scores, np.zeros((3, 3), bool))
        assert not ok and "empty disc" in reason


def test_check_is_timed_with_the_injected_clock():
    ticks = iter(range(100))
    monitor = build_monitor("lhd+ch:tau=0.25", clock=lambda: float(next(ticks)), labels=UAVID)
    hd = ids_to_colors(labels_image(40, 40))
    verdict = monitor.check(hd, Disc(20.0, 20.0, 5.0), ColourSegmenter())
    assert verdict.seconds == 1.0 and verdict.accepted
    verdict = monitor.check_scores(one_hot_scores(labels_image(3, 3)), np.ones((3, 3), bool))
    assert verdict.seconds == 1.0


# -- patch geometry -----------------------------------------------------------------------------
def full_disc_mask(h: int, w: int, disc: Disc) -> np.ndarray:
    rows, cols = np.mgrid[0:h, 0:w] + 0.5  # pixel centres in continuous image coordinates
    return (cols - disc.x) ** 2 + (rows - disc.y) ** 2 <= disc.radius_px**2


@settings(max_examples=80, deadline=None)
@given(
    x=st.floats(-10, 70), y=st.floats(-10, 50), r=st.floats(0.5, 30), margin=st.sampled_from([0.0, 0.25, 1.0])
)
def test_patch_holds_exactly_the_disc_pixels_inside_the_image(x, y, r, margin):
    h, w = 40, 60
    hd = np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8)
    disc = Disc(x, y, r)
    full = full_disc_mask(h, w, disc)
    if not full.any():
        with pytest.raises(ValueError, match="no pixel inside"):
            extract_patch(hd, disc, margin=margin)
        return
    p = extract_patch(hd, disc, margin=margin)
    x0, y0 = p.offset
    ph, pw = p.disc_mask.shape
    assert p.scale == 1.0 and p.rgb.shape == (ph, pw, 3)
    np.testing.assert_array_equal(p.rgb, hd[y0 : y0 + ph, x0 : x0 + pw])
    assert p.disc_mask.sum() == full.sum()  # every disc pixel inside the image, and no other
    np.testing.assert_array_equal(p.disc_mask, full[y0 : y0 + ph, x0 : x0 + pw])
    side = 2 * math.ceil(r * (1 + margin)) + 1
    assert ph <= side and pw <= side


def test_disc_partly_outside_the_image_keeps_only_inside_pixels():
    hd = np.zeros((50, 80, 3), np.uint8)
    p = extract_patch(hd, Disc(2.0, 45.0, 10.0), margin=0.25)
    assert p.offset == (0, 32) and p.disc_mask.shape == (18, 16)
    assert p.disc_mask.sum() == full_disc_mask(50, 80, Disc(2.0, 45.0, 10.0)).sum()


def test_downscaled_patch_keeps_the_disc_mask_conservative():
    hd = np.random.default_rng(3).integers(0, 256, (400, 500, 3), dtype=np.uint8)
    disc = Disc(250.3, 199.6, 120.0)
    p = extract_patch(hd, disc, margin=0.25, max_side=128)
    assert max(p.disc_mask.shape) == 128 and p.scale < 1 and p.rgb.shape[:2] == p.disc_mask.shape
    full = full_disc_mask(400, 500, disc)
    x0, y0 = p.offset
    rows, cols = np.nonzero(full)
    # every full-resolution disc pixel falls in a patch pixel of the mask
    pr = np.minimum(((rows - y0) * p.scale).astype(int), p.disc_mask.shape[0] - 1)
    pc = np.minimum(((cols - x0) * p.scale).astype(int), p.disc_mask.shape[1] - 1)
    assert p.disc_mask[pr, pc].all()
    area = math.pi * (disc.radius_px * p.scale) ** 2
    assert area <= p.disc_mask.sum() <= area * 1.15


# -- documentation examples run -----------------------------------------------------------------
@pytest.mark.parametrize("module", ["patches", "lhd", "spec", "build"])
def test_docstring_examples(module):
    mod = getattr(mon, module)
    failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


# -- the project's segmenter against the protocol -----------------------------------------------
@pytest.fixture(scope="module")
def project_segmenter():
    inference = pytest.importorskip("el.segmentation.inference")
    model = pytest.importorskip("el.segmentation.model")
    architectures = pytest.importorskip("el.segmentation.architectures")
    return inference.Segmenter(architectures.build_model(model.ArchConfig(widths=(8, 8, 8))), labels=UAVID)


def test_project_segmenter_implements_the_protocol(project_segmenter):
    assert isinstance(project_segmenter, PatchSegmenter)
    hd = np.random.default_rng(4).integers(0, 256, (80, 100, 3), dtype=np.uint8)
    for name in DEMO_GRID:
        verdict = build_monitor(name, labels=UAVID).check(hd, Disc(50.0, 40.0, 12.0), project_segmenter, seed=2)
        assert verdict.name == name and isinstance(verdict.accepted, bool)


def test_project_segmenter_mc_dropout_is_prefix_consistent(project_segmenter):
    rgb = np.random.default_rng(5).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    s30 = project_segmenter.mc_dropout(rgb, 30, 0.5, 3)
    np.testing.assert_array_equal(project_segmenter.mc_dropout(rgb, 10, 0.5, 3), s30[:10])


@pytest.mark.parametrize("lead", [(), (3,)])
def test_take_disc_is_the_same_for_any_memory_layout(lead):
    """Channels-last (cropped) scores, as the shipped network returns them, give the C-order result."""
    rng = np.random.default_rng(0)
    full = rng.random((*lead, 12, 11, 8)).astype(np.float32)  # (..., H, W, C) in memory
    strided = np.moveaxis(full, -1, -3)[..., :10, :9]  # (..., 8, 10, 9) view, classes innermost
    mask = rng.random((10, 9)) < 0.4
    got = take_disc(strided, mask)
    want = np.ascontiguousarray(strided)[..., mask]
    assert got.flags.c_contiguous and got.shape == (*lead, 8, int(mask.sum()))
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(take_disc(np.ascontiguousarray(strided), mask), want)


def test_mcd_check_samples_only_the_disc_box_with_the_same_verdict(project_segmenter):
    """In flight, MCD asks a window-capable segmenter for the disc's box only; the verdict is unchanged."""
    seg = project_segmenter
    windows = []

    class Spy:  # records the window; a segmenter without the keyword gets the full patch
        predict_patch = staticmethod(seg.predict_patch)

        def mc_dropout(self, rgb, n, keep_prob, seed, *, window=None):
            windows.append(window)
            return seg.mc_dropout(rgb, n, keep_prob, seed, window=window)

    class Plain:
        predict_patch = staticmethod(seg.predict_patch)

        @staticmethod
        def mc_dropout(rgb, n, keep_prob, seed):
            windows.append(None)
            return seg.mc_dropout(rgb, n, keep_prob, seed)

    hd = np.random.default_rng(0).integers(0, 255, (120, 160, 3), dtype=np.uint8)
    for spec in ("lhd+mcd:n=5,rho=0.5", "lhd+ch+mcd:tau=0.25,n=5,rho=0.75"):
        monitor = mon.build_monitor(spec, labels=UAVID)
        disc = Disc(80.5, 60.5, 20.0)
        a = monitor.check(hd, disc, Spy(), seed=3)
        b = monitor.check(hd, disc, Plain(), seed=3)
        assert (a.accepted, a.reason) == (b.accepted, b.reason)
        assert windows[-2] is not None and windows[-1] is None
        y0, y1, x0, x1 = windows[-2]
        assert y1 - y0 <= 41 and x1 - x0 <= 41  # the disc's box, not the 50 px patch
