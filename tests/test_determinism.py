"""Decisions that do not hang on the last bits (issue 60): the CM's ranking breaks exact ties by position (never by
the order the candidates were found in), and every ONNX Runtime session is opened with the same fixed options.

What cannot be fixed here (the network's float32 output differs in its last bits between CPUs) is measured in
docs/results.md, "Reproducibility across machines", and the README headline test allows for it
(``assurance.analysis.headline.REPRODUCIBILITY``).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from el.landing import ranking

GAP = 2.0**-20  # hazards of distinct candidates: no two of 953 test candidates lay closer than 1e-7


@st.composite
def ranked_candidates(draw, *, max_n: int = 12):
    """Hazards on a grid of GAP (some equal), their positions, and a perturbation of each hazard well inside half a
    grid step (what another CPU's arithmetic does to the last bits)."""
    n = draw(st.integers(1, max_n))
    steps = draw(st.lists(st.integers(0, 2**20), min_size=n, max_size=n))
    rows = draw(st.lists(st.integers(0, 575), min_size=n, max_size=n))
    cols = draw(st.lists(st.integers(0, 1023), min_size=n, max_size=n))
    noise = draw(st.lists(st.floats(-0.25, 0.25), min_size=n, max_size=n))
    hazards = np.array(steps, dtype=np.float64) * GAP
    return hazards, np.array(rows), np.array(cols), np.clip(hazards + np.array(noise) * GAP, 0.0, 1.0)


@settings(max_examples=200, deadline=None)
@given(ranked_candidates())
def test_distinct_hazards_rank_the_same_under_perturbations_below_half_their_gap(case):
    hazards, rows, cols, perturbed = case
    a, b = ranking.rank_order(perturbed, rows, cols), ranking.rank_order(hazards, rows, cols)
    assert [hazards[k] for k in a] == [hazards[k] for k in b]  # only equal hazards may change places


@settings(max_examples=200, deadline=None)
@given(ranked_candidates())
def test_equal_hazards_rank_by_row_then_column(case):
    hazards, rows, cols, _ = case
    order = ranking.rank_order(hazards, rows, cols)
    keys = [(hazards[k], rows[k], cols[k]) for k in order]
    assert keys == sorted(keys)


def test_the_ranking_is_a_function_of_the_values_not_of_their_order():
    rng = np.random.default_rng(0)
    hazards = np.round(rng.uniform(0, 1, 300), 2)  # many exact ties
    rows, cols = rng.integers(0, 576, 300), rng.integers(0, 1024, 300)
    perm = rng.permutation(300)
    first = [(rows[k], cols[k]) for k in ranking.rank_order(hazards, rows, cols)]
    again = [(rows[perm][k], cols[perm][k]) for k in ranking.rank_order(hazards[perm], rows[perm], cols[perm])]
    assert first == again


# ---- ONNX Runtime sessions -----------------------------------------------------------------------------------
def test_every_session_gets_the_fixed_options():
    ort = pytest.importorskip("onnxruntime")
    from el.segmentation import onnx_engine

    for threads in (None, 1, 2):
        options = onnx_engine.session_options(threads)
        assert options.execution_mode == ort.ExecutionMode.ORT_SEQUENTIAL
        assert options.inter_op_num_threads == 1
        assert options.graph_optimization_level == ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        assert onnx_engine.GRAPH_OPTIMIZATION == "ORT_ENABLE_ALL"
        assert options.intra_op_num_threads == (threads or 0)
        for key, value in onnx_engine.SESSION_CONFIG.items():
            assert options.get_session_config_entry(key) == value
    assert onnx_engine.SESSION_CONFIG == {"session.intra_op.allow_spinning": "0"}
    with pytest.raises(ValueError, match="threads"):
        onnx_engine.session_options(0)


def test_the_session_opened_is_opened_with_them(monkeypatch):
    pytest.importorskip("onnxruntime")
    from el.segmentation import onnx_engine
    from el.segmentation.onnx_engine import SHIPPED_DIR, read_checked

    seen = []
    real = onnx_engine.session_options
    monkeypatch.setattr(onnx_engine, "session_options", lambda threads=None: seen.append(threads) or real(threads))
    data, _ = read_checked(SHIPPED_DIR / "model.onnx")
    onnx_engine.open_session(data, "model.onnx", 1)
    assert seen == [1]


def test_the_thread_count_changes_no_bit_of_the_shipped_network():
    """1 and 2 intra-op threads: the same logits, bit for bit (MLAS splits the work, never a sum)."""
    pytest.importorskip("onnxruntime")
    from el.segmentation.onnx_engine import SHIPPED_DIR, open_session, read_checked

    data, _ = read_checked(SHIPPED_DIR / "model.onnx")
    x = np.random.default_rng(0).uniform(0, 1, (1, 3, 144, 256)).astype(np.float32)
    out = []
    for threads in (1, 2):
        session = open_session(data, "model.onnx", threads)
        out.append(session.run([session.get_outputs()[0].name], {session.get_inputs()[0].name: x})[0])
    assert out[0].tobytes() == out[1].tobytes()


# ---- the README headline's tolerance -------------------------------------------------------------------------
HEADER = ("Deployed configuration `learned:walk=score,threshold=0.8563253044730293`, "
          "calibration card `calibration.json` (sha256 `c496994321a2`); model sha256 `0d3dab88c2b0`; "
          "70 test scenes per perturbation (severity 3).\n\n"
          "| perturbation | unsafe landings, CM alone | unsafe landings, deployed | rate (one-sided 95% bound) | G_CM "
          "| G_RM [95%] | G* [95%] | recall / FP rate |\n|---|---|---|---|---|---|---|---|\n")
INTEL = HEADER + (  # the release run on one machine (README before 8517f08)
    "| brightness | 25 of 70 | 25 of 70 | 0.357 (0.462) | +0.301 | -0.014 [-0.092, +0.065] | +0.287 [+0.184, +0.382] "
    "| 0.173 / 0.048 |\n"
    "| fog | 29 of 70 | 28 of 70 | 0.400 (0.505) | +0.286 | +0.033 [-0.042, +0.109] | +0.318 [+0.218, +0.421] "
    "| 0.504 / 0.233 |\n")
EPYC = HEADER + (  # the same code's release run on an AMD EPYC (8517f08)
    "| brightness | 25 of 70 | 25 of 70 | 0.357 (0.462) | +0.302 | -0.020 [-0.098, +0.063] | +0.282 [+0.181, +0.376] "
    "| 0.173 / 0.048 |\n"
    "| fog | 29 of 70 | 28 of 70 | 0.400 (0.505) | +0.286 | +0.030 [-0.045, +0.107] | +0.316 [+0.217, +0.418] "
    "| 0.504 / 0.233 |\n")


def test_the_two_machines_release_runs_reproduce_each_other_within_the_tolerance():
    from assurance.analysis.headline import REPRODUCIBILITY, headline_differences

    assert INTEL != EPYC
    assert headline_differences(INTEL, EPYC) == headline_differences(EPYC, INTEL) == []
    assert REPRODUCIBILITY.gain(70) == pytest.approx(1 / 70 + 0.001)


def test_a_count_a_header_or_a_gain_beyond_one_decision_is_a_difference():
    from assurance.analysis.headline import Reproducibility, headline_differences

    more = EPYC.replace("| 25 of 70 | 25 of 70 | 0.357 (0.462)", "| 25 of 70 | 26 of 70 | 0.371 (0.477)")
    assert headline_differences(INTEL, more) == [
        "brightness: column 3 25 of 70 against 26 of 70 (must be equal)",
        "brightness: column 4 0.357 (0.462) against 0.371 (0.477) (must be equal)"]
    far = EPYC.replace("+0.302 |", "+0.318 |")
    assert headline_differences(INTEL, far) == ["brightness: column 5 +0.301 against +0.318 (tolerance 0.0153)"]
    assert headline_differences(INTEL, EPYC.replace("0d3dab88c2b0", "0d3dab88c2b1"))[0].startswith("'Deployed")
    assert headline_differences(INTEL, EPYC.replace("0.504 / 0.233", "0.520 / 0.233"))[0].startswith("fog: column 8")
    exact = Reproducibility(decisions=0, rounding=0.0, rate=0.0)
    first = headline_differences(INTEL, EPYC, exact)[0]
    assert first == "brightness: column 5 +0.301 against +0.302 (tolerance 0.0000)"
    assert headline_differences(INTEL, INTEL, exact) == []


# ---- the learned monitor's score -----------------------------------------------------------------------------
@settings(max_examples=50, deadline=None)
@given(st.lists(st.lists(st.floats(-50, 50), min_size=26, max_size=26), min_size=1, max_size=5),
       st.floats(-5, 5))
def test_the_learned_score_is_plain_sequential_arithmetic(rows, intercept):
    """No BLAS kernel and no SIMD exponential: the bits the C library's exp and column-by-column sums give, which
    are the same on every x86-64 CPU (OpenBLAS's AVX-512 and AVX2 kernels, NumPy's exp, differed)."""
    import math

    from el.monitors.learned import logistic

    terms = np.array(rows)
    expected = []
    for row in rows:
        z = 0.0
        for t in row:
            z += t
        z += intercept
        expected.append(1.0 / (1.0 + math.exp(-min(max(z, -500.0), 500.0))))
    assert logistic(terms, intercept).tolist() == expected
    assert float(logistic(terms[0], intercept)) == expected[0]


# ---- the softmax of a patch ----------------------------------------------------------------------------------
def test_the_class_softmax_of_any_patch_size_is_the_same_with_one_or_two_threads():
    """torch computes a row's partial last vector (and each thread's) with other code: the pixels are padded to a
    multiple of SOFTMAX_BLOCK, so neither the thread count nor the vector width (AVX2, AVX-512) changes a bit."""
    torch = pytest.importorskip("torch")
    from el.segmentation.inference import softmax_classes

    rng = np.random.default_rng(0)
    before = torch.get_num_threads()
    try:
        for h, w in ((300, 301), (517, 389), (61, 67)):
            x = torch.from_numpy(rng.normal(0, 5, (1, 8, h, w)).astype(np.float32))
            out = []
            for threads in (1, 2):
                torch.set_num_threads(threads)
                out.append(softmax_classes(x).contiguous().numpy().tobytes())
            assert out[0] == out[1]
            torch.set_num_threads(before)
            plain = torch.softmax(x, dim=1).numpy()
            assert np.abs(np.frombuffer(out[0], np.float32).reshape(plain.shape) - plain).max() <= 1e-6
        frame = torch.from_numpy(rng.normal(0, 5, (1, 8, 576, 1024)).astype(np.float32))
        assert softmax_classes(frame).numpy().tobytes() == torch.softmax(frame, dim=1).numpy().tobytes()
    finally:
        torch.set_num_threads(before)
