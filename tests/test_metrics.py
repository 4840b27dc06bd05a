"""Metrics (docs/architecture.md sections 4.4-4.5) against scikit-learn and scipy, and the paper's reference table."""

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import beta
from sklearn.metrics import (
    confusion_matrix,
    f1_score,
    matthews_corrcoef,
    precision_score,
    recall_score,
)

from assurance.analysis.metrics import (
    CI_METRICS,
    METRIC_NAMES,
    RESULT_COLUMNS,
    Counts,
    ImageReadout,
    ScenarioMetrics,
    bootstrap_ci,
    bootstrap_pooled_ci,
    clopper_pearson_interval,
    clopper_pearson_upper,
    confusion,
    monitor_metrics,
    rows_to_frame,
    safety_gains,
)
from assurance.analysis.reference import PERTURBATION_NAMES, load_reference, monitor_spec_name
from assurance.perturbations import PAPER_PERTURBATIONS

DESIGN_COLUMNS = (
    "perturbation, severity, monitor, images, candidates, g_cm, mcc, f1, precision, recall, "
    "fp_rate, g_rm, overhead_s, g_star, unsafe_landing_rate, unsafe_landing_ub95"
).split(", ")

flags = st.lists(st.tuples(st.booleans(), st.booleans()), min_size=0, max_size=60)


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, abs=1e-12)


# ---------------------------------------------------------------------------------------------
# Confusion counts and pooled metrics vs scikit-learn
# ---------------------------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(pairs=flags)
def test_metrics_agree_with_sklearn(pairs):
    unsafe = np.array([p[0] for p in pairs], dtype=bool)
    rejected = np.array([p[1] for p in pairs], dtype=bool)
    c = confusion(unsafe, rejected)
    assert c.total == len(pairs)
    if pairs:
        tn, fp, fn, tp = confusion_matrix(unsafe, rejected, labels=[False, True]).ravel()
        assert (c.tp, c.fp, c.tn, c.fn) == (tp, fp, tn, fn)
    m = monitor_metrics(c)
    assert tuple(m) == METRIC_NAMES
    if not pairs:
        assert all(math.isnan(v) for v in m.values())
        return
    nan = np.nan
    assert _same(m["precision"], precision_score(unsafe, rejected, zero_division=nan))
    assert _same(m["recall"], recall_score(unsafe, rejected, zero_division=nan))
    assert _same(m["f1"], f1_score(unsafe, rejected, zero_division=nan))
    assert _same(m["fp_rate"], fp / (fp + tn) if fp + tn else nan)
    margins = (tp + fp, tp + fn, tn + fp, tn + fn)
    if all(margins):
        assert m["mcc"] == pytest.approx(matthews_corrcoef(unsafe, rejected), abs=1e-12)
    else:  # scikit-learn says 0 where MCC is undefined; we say NaN
        assert math.isnan(m["mcc"])


def test_nan_when_undefined_never_zero():
    no_unsafe = monitor_metrics(confusion([False, False, False], [True, False, False]))
    assert math.isnan(no_unsafe["recall"]) and math.isnan(no_unsafe["mcc"])
    assert no_unsafe["precision"] == 0.0 and no_unsafe["fp_rate"] == pytest.approx(1 / 3)
    nothing_rejected = monitor_metrics(confusion([True, False], [False, False]))
    assert math.isnan(nothing_rejected["precision"]) and math.isnan(nothing_rejected["mcc"])
    assert nothing_rejected["recall"] == 0.0 and nothing_rejected["f1"] == 0.0
    all_safe_accepted = monitor_metrics(confusion([False, False], [False, False]))
    assert math.isnan(all_safe_accepted["f1"]) and all_safe_accepted["fp_rate"] == 0.0
    assert all(math.isnan(v) for v in monitor_metrics(Counts()).values())


def test_perfect_and_inverted_monitors():
    perfect = monitor_metrics(Counts(tp=5, fp=0, tn=7, fn=0))
    assert perfect == {"precision": 1.0, "recall": 1.0, "fp_rate": 0.0, "f1": 1.0, "mcc": 1.0}
    assert monitor_metrics(Counts(tp=0, fp=7, tn=0, fn=5))["mcc"] == -1.0


def test_counts_validation_and_sum():
    assert Counts(1, 2, 3, 4) + Counts(1, 1, 1, 1) == Counts(2, 3, 4, 5)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="tp"):
            Counts(tp=bad)
    with pytest.raises(ValueError, match="same length"):
        confusion([True], [True, False])
    with pytest.raises(ValueError, match="booleans"):
        confusion([2], [1])


def test_large_counts_do_not_overflow():
    big = 10**12
    m = monitor_metrics(Counts(tp=big, fp=big // 3, tn=big, fn=big // 5))
    assert -1 <= m["mcc"] <= 1 and math.isfinite(m["mcc"])


# ---------------------------------------------------------------------------------------------
# Safety gains
# ---------------------------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(h=st.lists(st.tuples(*[st.floats(0, 1)] * 3), min_size=1, max_size=30))
def test_gains_add_up(h):
    h0, ht, hd = (np.array(col) for col in zip(*h, strict=True))
    g = safety_gains(h0, ht, hd)
    assert np.array_equal(g.g_star, g.g_cm + g.g_rm)
    assert np.allclose(g.g_star, h0 - hd, atol=1e-12)
    assert g.g_cm.dtype == np.float64


def test_gain_signs_positive_is_safer():
    g = safety_gains(1.0, 0.3, 0.1)  # default on a road, CM picks 0.3, the monitor improves to 0.1
    assert (float(g.g_cm), float(g.g_rm), float(g.g_star)) == pytest.approx((0.7, 0.2, 0.9))


# ---------------------------------------------------------------------------------------------
# Clopper-Pearson
# ---------------------------------------------------------------------------------------------


def test_clopper_pearson_known_cases():
    assert clopper_pearson_upper(0, 70) == pytest.approx(0.0419, abs=5e-5)
    assert clopper_pearson_upper(0, 70) == pytest.approx(1 - 0.05 ** (1 / 70), rel=1e-9)
    assert clopper_pearson_upper(0, 10) == pytest.approx(0.2589, abs=5e-5)
    assert clopper_pearson_upper(1, 10) == pytest.approx(0.3942, abs=5e-5)
    assert clopper_pearson_upper(5, 5) == 1.0
    assert math.isnan(clopper_pearson_upper(0, 0))
    lo, hi = clopper_pearson_interval(5, 10)
    assert (lo, hi) == pytest.approx((0.1871, 0.8129), abs=5e-5)
    assert clopper_pearson_interval(0, 70) == pytest.approx((0.0, 1 - 0.025 ** (1 / 70)), rel=1e-9)


@pytest.mark.parametrize("k,n", [(0, 1), (1, 3), (3, 70), (20, 70), (69, 70), (7, 1000)])
def test_clopper_pearson_matches_beta_ppf(k, n):
    assert clopper_pearson_upper(k, n) == pytest.approx(beta.ppf(0.95, k + 1, n - k), rel=1e-12)
    assert clopper_pearson_upper(k, n, conf=0.99) == pytest.approx(beta.ppf(0.99, k + 1, n - k), rel=1e-12)
    lo, hi = clopper_pearson_interval(k, n)
    assert lo <= k / n <= hi
    assert hi == pytest.approx(beta.ppf(0.975, k + 1, n - k), rel=1e-12)
    if k:
        assert lo == pytest.approx(beta.ppf(0.025, k, n - k + 1), rel=1e-12)


@pytest.mark.parametrize("k,n,conf", [(-1, 5, 0.95), (6, 5, 0.95), (1, 5, 1.0), (1.0, 5, 0.95)])
def test_clopper_pearson_rejects_bad_input(k, n, conf):
    with pytest.raises(ValueError):
        clopper_pearson_upper(k, n, conf)


# ---------------------------------------------------------------------------------------------
# Bootstrap
# ---------------------------------------------------------------------------------------------


def test_bootstrap_contains_mean_and_is_reproducible():
    x = np.random.default_rng(0).normal(0.3, 0.2, size=70)
    lo, hi = bootstrap_ci(x, seed=1)
    assert lo < x.mean() < hi
    assert bootstrap_ci(x, seed=1) == (lo, hi)
    assert bootstrap_ci(x, seed=2) != (lo, hi)
    assert bootstrap_ci(x, seed=np.random.default_rng(1)) == (lo, hi)
    # the generic (per-resample) path gives the same numbers as the vectorised one
    assert bootstrap_ci(x, lambda s: float(np.mean(s)), seed=1) == pytest.approx((lo, hi), abs=1e-12)


def test_bootstrap_narrows_with_more_data():
    rng = np.random.default_rng(3)
    small = bootstrap_ci(rng.normal(size=20), seed=0)
    large = bootstrap_ci(rng.normal(size=2000), seed=0)
    assert large[1] - large[0] < 0.5 * (small[1] - small[0])


def test_bootstrap_median_and_edge_cases():
    x = np.arange(11.0)
    lo, hi = bootstrap_ci(x, np.median, n_boot=500, seed=0)
    assert lo <= 5 <= hi
    assert bootstrap_ci(np.full(5, 0.25), seed=0) == (0.25, 0.25)
    assert all(math.isnan(v) for v in bootstrap_ci([], seed=0))
    with pytest.raises(ValueError, match="n_boot"):
        bootstrap_ci(x, n_boot=0)
    with pytest.raises(ValueError, match="conf"):
        bootstrap_ci(x, conf=95)
    with pytest.raises(ValueError, match="one-dimensional"):
        bootstrap_ci(np.ones((2, 2)))


def _random_counts(n_images: int, seed: int) -> list[Counts]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_images):
        n = int(rng.integers(1, 15))
        unsafe = rng.random(n) < 0.4
        rejected = np.where(unsafe, rng.random(n) < 0.8, rng.random(n) < 0.15)
        out.append(confusion(unsafe, rejected))
    return out


@pytest.mark.parametrize("metric", METRIC_NAMES)
def test_pooled_bootstrap_contains_pooled_value(metric):
    per_image = _random_counts(70, seed=4)
    point = monitor_metrics(sum(per_image, Counts()))[metric]
    lo, hi = bootstrap_pooled_ci(per_image, metric, seed=0)
    assert lo <= point <= hi and lo < hi
    as_array = np.array([c.as_array() for c in per_image])
    assert bootstrap_pooled_ci(as_array, metric, seed=0) == (lo, hi)  # rows of (tp, fp, tn, fn) work too
    more = bootstrap_pooled_ci(_random_counts(700, seed=4), metric, seed=0)
    assert more[1] - more[0] < hi - lo


def test_pooled_bootstrap_undefined_and_bad_name():
    no_unsafe = [Counts(tp=0, fp=1, tn=3, fn=0)] * 5
    assert all(math.isnan(v) for v in bootstrap_pooled_ci(no_unsafe, "recall"))
    assert all(math.isnan(v) for v in bootstrap_pooled_ci([], "precision"))
    with pytest.raises(ValueError, match="unknown metric"):
        bootstrap_pooled_ci(no_unsafe, "accuracy")


# ---------------------------------------------------------------------------------------------
# ScenarioMetrics
# ---------------------------------------------------------------------------------------------


def _readouts(n_images: int, seed: int) -> list[ImageReadout]:
    rng = np.random.default_rng(seed)
    records = []
    for i in range(n_images):
        n = int(rng.integers(0, 12))
        unsafe = rng.random(n) < 0.4
        rejected = np.where(unsafe, rng.random(n) < 0.85, rng.random(n) < 0.2)
        h0 = float(rng.choice([1.0, rng.uniform(0, 0.5)]))
        if n == 0:
            h_top, h_dec = None, h0
        else:
            h_top = 1.0 if unsafe[0] else float(rng.uniform(0, 0.5))
            accepted = np.flatnonzero(~rejected)
            first = accepted[0] if accepted.size else None
            h_dec = h0 if first is None else (1.0 if unsafe[first] else float(rng.uniform(0, 0.5)))
        records.append(
            ImageReadout(
                unsafe=unsafe,
                rejected=rejected,
                h_default=h0,
                h_top=h_top,
                h_decision=h_dec,
                overhead_s=float(rng.uniform(0.1, 3.0)),
                image_id=f"{i:06d}",
            )
        )
    return records


def test_scenario_columns_are_designs():
    assert RESULT_COLUMNS[: len(DESIGN_COLUMNS)] == tuple(DESIGN_COLUMNS)
    tail = RESULT_COLUMNS[len(DESIGN_COLUMNS) :]
    assert tail == tuple(f"{n}_{s}95" for n in CI_METRICS for s in ("lo", "hi"))
    assert len(set(RESULT_COLUMNS)) == len(RESULT_COLUMNS)


def test_scenario_metrics_row():
    records = _readouts(70, seed=1)
    sm = ScenarioMetrics("fog", 3, "lhd+ch:tau=0.25", seed=0)
    sm.extend(records)
    row = sm.compute()
    assert tuple(row) == RESULT_COLUMNS
    assert (row["perturbation"], row["severity"], row["monitor"], row["images"]) == (
        "fog",
        3,
        "lhd+ch:tau=0.25",
        70,
    )
    assert row["candidates"] == sum(r.unsafe.size for r in records)

    pooled = monitor_metrics(sum((r.counts for r in records), Counts()))
    for name in METRIC_NAMES:
        assert row[name] == pytest.approx(pooled[name], abs=1e-15)
        per_image = [r.counts for r in records]
        assert (row[f"{name}_lo95"], row[f"{name}_hi95"]) == bootstrap_pooled_ci(per_image, name, seed=0)

    h0 = np.array([r.h_default for r in records])
    ht = np.array([r.h_default if r.h_top is None else r.h_top for r in records])
    hd = np.array([r.h_decision for r in records])
    assert row["g_cm"] == pytest.approx(np.mean(h0 - ht), abs=1e-12)
    assert row["g_rm"] == pytest.approx(np.mean(ht - hd), abs=1e-12)
    assert row["g_star"] == pytest.approx(row["g_cm"] + row["g_rm"], abs=1e-12)
    assert (row["g_star_lo95"], row["g_star_hi95"]) == bootstrap_ci(h0 - ht + (ht - hd), seed=0)
    overhead = [r.overhead_s for r in records]
    assert row["overhead_s"] == pytest.approx(np.mean(overhead))
    assert (row["overhead_s_lo95"], row["overhead_s_hi95"]) == bootstrap_ci(overhead, seed=0)
    for name in CI_METRICS:
        assert row[f"{name}_lo95"] <= row[name] <= row[f"{name}_hi95"], name

    k = int(np.sum(hd >= 1.0))
    assert row["unsafe_landing_rate"] == k / 70
    assert row["unsafe_landing_ub95"] == clopper_pearson_upper(k, 70)
    assert (row["unsafe_landing_rate_lo95"], row["unsafe_landing_rate_hi95"]) == clopper_pearson_interval(
        k, 70
    )

    frame = rows_to_frame([row, row])
    assert list(frame.columns) == list(RESULT_COLUMNS) and len(frame) == 2


def test_scenario_is_deterministic_and_order_free():
    records = _readouts(30, seed=2)
    a = ScenarioMetrics("fog", 3, "lhd", seed=5)
    a.extend(records)
    b = ScenarioMetrics("fog", 3, "lhd", seed=5)
    b.extend(records[::-1])  # parallel workers may report in any order
    ra, rb = a.compute(), b.compute()
    assert all(_same(ra[k], rb[k]) if isinstance(ra[k], float) else ra[k] == rb[k] for k in RESULT_COLUMNS)
    c = ScenarioMetrics("fog", 3, "lhd", seed=6)
    c.extend(records)
    assert c.compute()["g_star_lo95"] != ra["g_star_lo95"]


def test_zero_unsafe_landings_in_70_images():
    sm = ScenarioMetrics("none", None, "lhd")
    for i in range(70):
        sm.update(
            ImageReadout(
                unsafe=[False, True],
                rejected=[False, True],
                h_default=1.0,
                h_top=0.2,
                h_decision=0.2,
                image_id=str(i),
            )
        )
    row = sm.compute()
    assert row["unsafe_landing_rate"] == 0.0
    assert row["unsafe_landing_ub95"] == pytest.approx(0.0419, abs=5e-5)
    assert row["unsafe_landing_rate_lo95"] == 0.0
    assert row["g_cm"] == pytest.approx(0.8) and row["g_rm"] == 0.0 and row["mcc"] == 1.0


def test_empty_scenario_is_nan():
    row = ScenarioMetrics("fog", 3, "lhd").compute()
    assert tuple(row) == RESULT_COLUMNS and row["images"] == 0 and row["candidates"] == 0
    assert all(math.isnan(row[k]) for k in RESULT_COLUMNS[5:])


def test_undefined_metric_has_no_interval():
    sm = ScenarioMetrics("fog", 3, "lhd")
    sm.update(ImageReadout(unsafe=[False], rejected=[False], h_default=0.5, h_top=0.1, h_decision=0.1))
    row = sm.compute()
    assert math.isnan(row["recall"]) and math.isnan(row["recall_lo95"]) and math.isnan(row["mcc_hi95"])
    assert row["fp_rate"] == 0.0 and row["g_cm"] == pytest.approx(0.4)


def test_no_candidate_falls_back_to_default():
    r = ImageReadout(unsafe=[], rejected=[], h_default=0.7, h_top=None, h_decision=0.7)
    assert r.h_core == 0.7 and r.counts == Counts() and not r.decision_unsafe
    sm = ScenarioMetrics("fog", 3, "lhd")
    sm.update(r)
    row = sm.compute()
    assert row["g_cm"] == 0.0 and row["g_rm"] == 0.0 and row["candidates"] == 0


def test_decision_unsafe_flag():
    assert ImageReadout(unsafe=[True], rejected=[False], h_default=0, h_top=1, h_decision=1).decision_unsafe
    override = ImageReadout(
        unsafe=[True], rejected=[False], h_default=0, h_top=1, h_decision=1, decision_unsafe=False
    )
    assert not override.decision_unsafe


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"h_default": 1.5}, "h_default"),
        ({"h_decision": float("nan")}, "h_decision"),
        ({"h_top": -0.1}, "h_top"),
        ({"h_top": None}, "no candidate"),
        ({"rejected": [True]}, "same length"),
        ({"overhead_s": -1.0}, "overhead_s"),
        ({"unsafe": [[True, False]], "rejected": [[True, False]]}, "one-dimensional"),
    ],
)
def test_readout_validation(kwargs, match):
    base = {
        "unsafe": [True, False],
        "rejected": [True, False],
        "h_default": 1.0,
        "h_top": 1.0,
        "h_decision": 0.2,
    }
    with pytest.raises(ValueError, match=match):
        ImageReadout(**{**base, **kwargs})


def test_scenario_validation():
    sm = ScenarioMetrics("fog", 3, "lhd")
    r = ImageReadout(unsafe=[True], rejected=[True], h_default=1, h_top=1, h_decision=0, image_id="a")
    sm.update(r)
    with pytest.raises(ValueError, match="already"):
        sm.update(r)
    with pytest.raises(TypeError):
        sm.update({"unsafe": [True]})
    with pytest.raises(ValueError, match="n_boot"):
        ScenarioMetrics("fog", 3, "lhd", n_boot=0)
    with pytest.raises(ValueError, match="severity"):
        ScenarioMetrics("fog", "3", "lhd")
    with pytest.raises(ValueError, match="no candidate"):
        ImageReadout(unsafe=[], rejected=[], h_default=0, h_top=0.5, h_decision=0)


# ---------------------------------------------------------------------------------------------
# The paper's reference table
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ref() -> pd.DataFrame:
    return load_reference()


def test_reference_shape_and_names(ref):
    assert len(ref) == 126
    assert set(ref["perturbation"]) == set(PAPER_PERTURBATIONS) == set(PERTURBATION_NAMES.values())
    assert ref.groupby("perturbation").size().eq(21).all()
    assert not ref.duplicated(["perturbation", "monitor"]).any()
    for name in ("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.5", "lhd+ch+mcd:tau=0.125,n=30,rho=0.9"):
        assert name in set(ref["monitor"])
    assert set(RESULT_COLUMNS[:14]) <= set(ref.columns)
    assert (ref["images"] == 70).all() and ref["candidates"].isna().all()
    assert ref.loc[ref.perturbation == "none", "severity"].isna().all()
    assert (ref.loc[ref.perturbation != "none", "severity"] == 3).all()


def test_reference_monitor_names_match_the_monitor_specs(ref):
    spec = pytest.importorskip("el.monitors.spec")
    assert set(ref["monitor"]) == set(spec.PAPER_GRID)
    for name in ref["monitor"]:
        assert spec.monitor_name(name) == name


def test_reference_table_one_row_values(ref):
    row = ref[(ref.perturbation == "motion_blur") & (ref.monitor == "lhd+ch+mcd:tau=0.25,n=10,rho=0.9")].iloc[
        0
    ]
    assert (row.mcc, row.f1, row.precision, row.recall, row.fp_rate) == (0.466, 0.711, 0.563, 0.966, 0.541)
    assert (row.g_cm, row.g_rm, row.overhead_s, row.g_star) == (0.321, 0.008, 23.83, 0.329)
    assert (row.tau, row.n_mcd, row.rho, row.kind) == (0.25, 10, 0.9, "lhd+ch+mcd")


def test_reference_flags_exactly_the_known_typo(ref):
    flagged = ref[ref.flag != ""]
    assert len(flagged) == 1
    row = flagged.iloc[0]
    assert (row.perturbation, row.monitor) == ("none", monitor_spec_name(tau=0.25, n_mcd=30, rho=0.75))
    assert row.precision == 0.964  # the published value is kept
    assert "0.694" in row.flag


def test_reference_is_consistent_with_pooled_counts(ref):
    """The published figures fit pooled confusion counts: rebuilt from the implied share of unsafe
    candidates, recall and FP rate, our metric functions give back MCC, F1 and precision."""
    ok = ref[ref.flag == ""]
    assert (ok.g_star - ok.g_cm - ok.g_rm).abs().max() <= 0.0015
    assert np.allclose(ok.fn_rate, 1 - ok.recall, atol=1e-9)
    lhd_none = ok[(ok.perturbation == "none") & (ok.monitor == "lhd")].iloc[0]
    assert lhd_none.unsafe_share == pytest.approx(0.36, abs=0.005)  # "about 36%", docs/architecture.md section 5.2
    scale = 10**7
    for r in ok.itertuples():
        pos, neg = scale * r.unsafe_share, scale * (1 - r.unsafe_share)
        c = Counts(
            tp=round(pos * r.recall),
            fn=round(pos * (1 - r.recall)),
            fp=round(neg * r.fp_rate),
            tn=round(neg * (1 - r.fp_rate)),
        )
        m = monitor_metrics(c)
        assert m["mcc"] == pytest.approx(r.mcc, abs=0.002)
        assert m["f1"] == pytest.approx(r.f1, abs=0.002)
        assert m["precision"] == pytest.approx(r.precision, abs=1e-6)


def test_reference_loads_another_copy(tmp_path, ref):
    path = tmp_path / "copy.csv"
    path.write_text("# a comment\n" + "\n".join(open_packaged_lines()))
    assert load_reference(path).equals(ref)
    bad = tmp_path / "bad.csv"
    bad.write_text("Perturbation,Threshold\nFog,-1\n")
    with pytest.raises(ValueError, match="lacks columns"):
        load_reference(bad)


def open_packaged_lines() -> list[str]:
    from importlib import resources

    text = (resources.files("assurance") / "data" / "guerin2022_results.csv").read_text(encoding="utf-8")
    return [line for line in text.splitlines() if not line.startswith("#")]
