"""The requirement targets: EL-R10 at the configured confidence, targets as validated parameters, requirement
texts rendered from them, and the targets bound to the requirement results and the evidence gate."""

from __future__ import annotations

import pandas as pd
import pytest
from scipy import stats

from assurance import requirements as rq
from assurance.analysis.metrics import clopper_pearson_upper


# ------------------------------------------------------------------------------------------------
# EL-R10 honours its confidence
# ------------------------------------------------------------------------------------------------
def _table(k: int, n: int, monitor: str = "m") -> pd.DataFrame:
    # the table's fixed 95% column is left out on purpose: the check computes its own bound
    return pd.DataFrame([{"perturbation": "none", "severity": 3, "monitor": monitor, "images": n,
                          "unsafe_landing_rate": k / n}])


def test_one_sided_bound_known_values_and_the_two_sided_relation():
    assert clopper_pearson_upper(0, 70, 0.95) == pytest.approx(0.0419, abs=5e-5)
    assert clopper_pearson_upper(0, 300, 0.99) == pytest.approx(0.0152, abs=5e-5)
    assert clopper_pearson_upper(0, 300, 0.99) == pytest.approx(1 - 0.01 ** (1 / 300), rel=1e-12)
    for k, n, conf in ((0, 300, 0.99), (3, 300, 0.95), (7, 70, 0.9)):
        one_sided = stats.binomtest(k, n, alternative="less").proportion_ci(confidence_level=conf, method="exact")
        two_sided = stats.binomtest(k, n).proportion_ci(confidence_level=2 * conf - 1, method="exact")
        assert clopper_pearson_upper(k, n, conf) == pytest.approx(one_sided.high, rel=1e-9)
        assert one_sided.high == pytest.approx(two_sided.high, rel=1e-9)  # one-sided c = two-sided 2c - 1


def test_el_r10_0_of_300_at_99_percent_is_not_verified():
    """The reported bug: 0 unsafe landings in 300 images, bound 0.01 at 99%: the 99% bound is 0.0152, so the
    sample cannot show 0.01 (the 95% bound, 0.0099, would have)."""
    at95 = rq.check_unsafe_landing_bound(_table(0, 300), "m", 0.01, ["none"], 0.95)
    at99 = rq.check_unsafe_landing_bound(_table(0, 300), "m", 0.01, ["none"], 0.99)
    assert at95.status == rq.PASS
    assert at99.status == rq.INSUFFICIENT and "99% confidence" in at99.summary
    assert at99.rows[0]["upper_bound"] == pytest.approx(0.015233, abs=1e-6)
    assert at99.rows[0]["confidence"] == "99%" and "99%" in at99.name


def test_el_r10_fails_at_99_where_95_passes_and_passes_at_90_where_95_fails():
    # 3 of 300, bound 0.03: 95% bound 0.0256 <= 0.03, 99% bound 0.0331 > 0.03 (and 0 of 300 would show it)
    assert rq.check_unsafe_landing_bound(_table(3, 300), "m", 0.03, ["none"], 0.95).status == rq.PASS
    strict = rq.check_unsafe_landing_bound(_table(3, 300), "m", 0.03, ["none"], 0.99)
    assert strict.status == rq.FAIL and "one-sided 99% upper bound > 0.03" in strict.summary
    assert strict.rows[0]["over_bound_by"] == pytest.approx(0.033093 - 0.03, abs=1e-6)
    # the other way: 0 of 50, bound 0.05: 95% bound 0.058 cannot show it, 90% bound 0.045 does
    assert rq.check_unsafe_landing_bound(_table(0, 50), "m", 0.05, ["none"], 0.95).status == rq.INSUFFICIENT
    loose = rq.check_unsafe_landing_bound(_table(0, 50), "m", 0.05, ["none"], 0.90)
    assert loose.status == rq.PASS and "90%" in loose.summary


def test_the_campaign_check_passes_the_registry_confidence():
    params = {**rq.load_registry().parameters, "unsafe_landing_bound": 0.01, "confidence": 0.99,
              "deployed_monitor": "m", "required_perturbations": ["none"]}
    ctx = rq.CheckContext("no-run", params, table=_table(0, 300))
    ev = rq.CHECKS["unsafe_landing_bound"](ctx)
    assert ev.status == rq.INSUFFICIENT and ev.requirement == "EL-R10" and "99%" in ev.summary


# ------------------------------------------------------------------------------------------------
# Targets as parameters, texts rendered from them
# ------------------------------------------------------------------------------------------------
def test_every_number_the_checks_read_is_a_target_of_the_shipped_registry():
    reg = rq.load_registry()
    read = {p for c in rq.CHECKS.values() for p in c.parameters}
    assert read <= set(rq.TARGETS) and set(rq.REQUIRED_TARGETS) <= set(reg.parameters)
    assert {"radius_m", "beta", "confidence", "unsafe_landing_bound"} <= read
    assert reg.targets == {} and reg.targets_source is None
    texts = [t for r in reg for t in (r.title, r.text, r.rationale, r.acceptance, r.domain, r.verification_method)]
    assert not [t for t in texts + list(reg.operating_domain.values()) if "{" in t or "}" in t]
    assert "R = 2 m" in reg["EL-R02"].text and "95%" in reg["EL-R10"].verification_method


def test_changed_targets_show_in_the_rendered_texts():
    base = rq.load_registry()
    reg = base.with_targets({"radius_m": 2.5, "beta": 1.9, "confidence": 0.975, "unsafe_landing_bound": 0.01,
                             "pose_error": {"height": 0.1, "pitch": 0.15}}, source="my-targets.json")
    assert "R = 2.5 m" in reg["EL-R02"].text and "10% in height and 15% in pitch" in reg["EL-R02"].text
    assert "R = 2.5 m" in reg["EL-R02"].acceptance and "R = 2 m" not in reg["EL-R02"].acceptance
    assert "at most 1% in every scenario, shown with 97.5% confidence" in reg["EL-R10"].text
    assert "one-sided 97.5% upper bound <= 0.01" in reg["EL-R10"].acceptance
    assert "beta = 1.9" in reg["EL-R14"].acceptance and "R = 2.5 m" in reg["EL-R14"].acceptance
    assert reg.operating_domain["safety_radius"] == "R = 2.5 m with safety coefficient beta = 1.9"
    assert reg.parameters["radius_m"] == 2.5 and reg.defaults["radius_m"] == 2.0
    assert reg.targets_source == "my-targets.json" and reg.sha256 == base.sha256  # the same registry file
    assert reg.parameters_sha256 != base.parameters_sha256
    assert base.with_targets({"radius_m": 2.0}).parameters_sha256 == base.parameters_sha256
    # overrides stack, and the registry they came from is untouched
    again = reg.with_targets({"radius_m": 3})
    assert again.parameters["radius_m"] == 3.0 and again.parameters["beta"] == 1.9
    assert "R = 2 m" in base["EL-R02"].text
    assert rq.load_registry(targets={"radius_m": 2.5}).parameters == base.with_targets({"radius_m": 2.5}).parameters


def test_render_text_formats_and_refuses():
    params = {"radius_m": 2.0, "confidence": 0.975, "pose_error": {"height": 0.2, "pitch": 0.1},
              "required_perturbations": ["none", "fog"], "deployed_monitor": "lhd", "calibration_card": None}
    out = rq.render_text("R = {radius_m:g} m at {confidence:pct} ({confidence:.0%}); +-{pose_error.pitch:pct}; "
                         "{required_perturbations}; {pose_error:pct}; {calibration_card}; {{literal}}", params)
    assert out == "R = 2 m at 97.5% (98%); +-10%; none, fog; height 20%, pitch 10%; none; {literal}"
    for bad, why in (("{radius}", "names no parameter; known: radius_m"),
                     ("{radius_m.__class__}", "has no key '__class__'"),
                     ("{pose_error[height]}", "only a parameter name"),
                     ("{radius_m!r}", "conversions"),
                     ("{radius_m:{confidence}}", "nested"),
                     ("{deployed_monitor:.0%}", "deployed_monitor"),
                     ("{deployed_monitor:pct}", "needs a number"),
                     ("{pose_error.yaw}", "has no key 'yaw'"),
                     ("{radius_m", "malformed")):
        with pytest.raises(rq.TargetError, match=why.replace("[", r"\[").replace("(", r"\(")):
            rq.render_text(bad, params)


def _registry_file(tmp_path, edit):
    import yaml

    doc = yaml.safe_load(rq.default_registry_path().read_text(encoding="utf-8"))
    edit(doc)
    path = tmp_path / "reg.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_an_unknown_placeholder_is_refused_at_load(tmp_path):
    def edit(doc):
        doc["requirements"][1]["text"] = "The safety radius R = {radius} m holds."

    path = _registry_file(tmp_path, edit)
    with pytest.raises(rq.RegistryError, match=r"requirements\[1\] \(EL-R02\): field 'text': placeholder "
                                               r"\{radius\} names no parameter") as exc:
        rq.load_registry(path)
    assert str(path) in str(exc.value) and "radius_m" in str(exc.value)

    def edit_domain(doc):
        doc["operating_domain"]["safety_radius"] = "R = {R} m"

    with pytest.raises(rq.RegistryError, match="operating_domain: field 'safety_radius'"):
        rq.load_registry(_registry_file(tmp_path, edit_domain))


@pytest.mark.parametrize("edit,message", [
    (lambda d: d["parameters"].pop("radius_m"), "missing 'radius_m'"),
    (lambda d: d["parameters"].update(beta=0.8), r"parameters.beta = 0.8: must be a safety coefficient beta >= 1"),
    (lambda d: d["parameters"].update(confidence=0.3), r"parameters.confidence = 0.3: must be a number in \[0.5, 1\)"),
])
def test_registry_parameters_are_checked_like_targets(tmp_path, edit, message):
    path = _registry_file(tmp_path, edit)
    with pytest.raises(rq.RegistryError, match=message) as exc:
        rq.load_registry(path)
    assert str(path) in str(exc.value)


@pytest.mark.parametrize("name,value,allowed", [
    ("unsafe_landing_bound", 0, r"a number in \(0, 1\)"),
    ("unsafe_landing_bound", 1.0, r"a number in \(0, 1\)"),
    ("unsafe_landing_bound", "0.05", r"a number in \(0, 1\)"),
    ("unsafe_landing_bound", True, r"a number in \(0, 1\)"),
    ("confidence", 0.4, r"a number in \[0.5, 1\)"),
    ("confidence", 1.0, r"a number in \[0.5, 1\)"),
    ("time_budget_s", 0, "a number of seconds > 0"),
    ("time_budget_s", float("nan"), "a number of seconds > 0"),
    ("radius_m", -2.0, "a safety radius R in metres > 0"),
    ("radius_m", float("inf"), "a safety radius R in metres > 0"),
    ("beta", 0.99, "a safety coefficient beta >= 1"),
    ("min_images_per_perturbation", 0, "an integer >= 1"),
    ("min_images_per_perturbation", 2.5, "an integer >= 1"),
    ("rerun_shards", -1, "an integer >= 0"),
    ("pose_error", {"height": 0.2}, r"a mapping \{height: e, pitch: e\}"),
    ("pose_error", {"height": 1.0, "pitch": 0.2}, r"each in \[0, 1\)"),
    ("required_perturbations", [], "a non-empty list of distinct perturbation names"),
    ("required_perturbations", ["fog", "fog"], "a non-empty list of distinct perturbation names"),
    ("deployed_monitor", "", "a monitor configuration"),
    ("calibration_card", 3, "a path to a calibration card"),
])
def test_a_bad_override_names_key_value_and_what_is_allowed(name, value, allowed):
    with pytest.raises(rq.TargetError, match=allowed) as exc:
        rq.load_registry(targets={name: value}, targets_source="t.json")
    assert f"t.json.{name} = {value!r}" in str(exc.value)


def test_an_unknown_target_names_the_known_ones():
    with pytest.raises(rq.TargetError, match=r"targets: unknown target 'radius'; known: deployed_monitor, .*radius_m"):
        rq.load_registry(targets={"radius": 2.5})
    with pytest.raises(rq.TargetError, match="must be a mapping"):
        rq.load_registry().with_targets(["radius_m"])  # type: ignore[arg-type]
    assert rq.load_registry(targets={"calibration_card": None}).parameters["calibration_card"] is None


def test_a_registry_parameter_without_a_registered_check_keeps_its_type(tmp_path):
    path = _registry_file(tmp_path, lambda d: d["parameters"].update(max_examined=5))
    reg = rq.load_registry(path, targets={"max_examined": 7})
    assert reg.parameters["max_examined"] == 7
    with pytest.raises(rq.TargetError, match=r"max_examined = 'seven': must be of the registry default's type"):
        reg.with_targets({"max_examined": "seven"})


def test_targets_file(tmp_path):
    (tmp_path / "t.json").write_text('{"confidence": 0.99}')
    assert rq.read_targets_file(tmp_path / "t.json") == {"confidence": 0.99}
    (tmp_path / "list.json").write_text("[1]")
    (tmp_path / "bad.json").write_text("{")
    for name, why in (("list.json", "must hold a JSON object"), ("bad.json", "not valid JSON"),
                      ("missing.json", "cannot read")):
        with pytest.raises(rq.TargetError, match=why) as exc:
            rq.read_targets_file(tmp_path / name)
        assert name in str(exc.value)


def test_results_and_gate_are_bound_to_the_targets(tmp_path):
    from assurance.evidence import binding_problems

    reg = rq.load_registry(targets={"confidence": 0.99}, targets_source="t.json")
    doc = rq.results_document(reg, rq.evaluate(reg, []))
    assert doc["registry"]["targets"] == {"confidence": 0.99} and doc["registry"]["targets_source"] == "t.json"
    assert doc["registry"]["parameters_sha256"] == reg.parameters_sha256 == rq.targets_sha256(reg.parameters)
    doc["context"] = {"run_digest": "d" * 64, "code_sha256": "c" * 64}
    args = (doc, "d" * 64, "c" * 64, reg.sha256, tmp_path / "r.json")
    assert binding_problems(*args, parameters_sha=reg.parameters_sha256) == []
    other = rq.load_registry()
    problems = binding_problems(*args, parameters_sha=other.parameters_sha256)
    assert len(problems) == 1 and 'other requirement targets (their overrides: {"confidence": 0.99})' in problems[0]


def test_shipped_targets_are_the_flight_codes_safety_params():
    """The registry's default R and beta are what the flight code plans with (el.geometry.camera.SafetyParams())."""
    from el.geometry.camera import SafetyParams
    from el.geometry.config import CoreConfig

    p = rq.load_registry().parameters
    assert (p["radius_m"], p["beta"]) == (SafetyParams().radius_m, SafetyParams().beta)
    assert CoreConfig().safety == SafetyParams()
    need = rq.check_pose_margin(CoreConfig(), (3840, 2160), p["pose_error"]).rows[0]["required_beta"]
    assert 1.5 < need < p["beta"]  # docs/architecture.md 2.3: about 1.56 for +-20%, so 1.7 has margin
