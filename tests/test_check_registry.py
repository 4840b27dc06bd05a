"""The check registry (``assurance.requirements.CHECKS``): consistent with the requirement registry, and the
only place that ties a campaign check to a requirement (docs/architecture.md section 4.8)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from assurance import requirements as rq
from assurance.requirements import catalogue

ROOT = Path(__file__).resolve().parent.parent


def test_every_check_judges_a_registry_requirement_and_reads_registry_parameters():
    reg = rq.load_registry()
    for c in rq.CHECKS.values():
        assert c.requirement in reg, c.name
        assert "campaign" in reg[c.requirement].verification_kind, c.name
        assert set(c.parameters) <= set(reg.parameters), c.name
        assert set(c.artefacts) <= set(rq.ARTEFACTS), c.name


def test_every_campaign_requirement_has_a_check_and_at_most_one_in_the_report():
    for req in rq.load_registry():
        if "campaign" in req.verification_kind:
            assert rq.checks_of(req.id), f"{req.id} is verified by campaign but no check is registered"
        assert sum(c.in_report for c in rq.checks_of(req.id)) <= 1, req.id


def test_the_evidence_package_names_no_requirement_id():
    for path in sorted((ROOT / "assurance" / "evidence").glob("*.py")):
        assert "EL-R" not in path.read_text(encoding="utf-8"), path


def test_registering_a_check_and_running_it_on_a_context(monkeypatch):
    monkeypatch.setattr(catalogue, "CHECKS", dict(catalogue.CHECKS))

    @catalogue.check("EL-R99", parameters=("time_budget_s",), artefacts=("results_table",), in_report=False)
    def budget_is_positive(ctx: rq.CheckContext) -> rq.Evidence:
        ok = ctx.parameters["time_budget_s"] > 0
        return rq.Evidence("budget", rq.PASS if ok else rq.FAIL, f"{len(ctx.images)} image rows")

    images = pd.DataFrame({"fault": ["", ""]})
    ev = catalogue.CHECKS["budget_is_positive"](rq.CheckContext("run", {"time_budget_s": 1.0}, images=images))
    assert (ev.requirement, ev.status, ev.summary) == ("EL-R99", rq.PASS, "2 image rows")
    assert catalogue.artefacts_of("EL-R99") == ["results_table"]
    assert catalogue.requirements_reading("time_budget_s")[-1] == "EL-R99"
    with pytest.raises(ValueError, match="already registered"):
        catalogue.check("EL-R98")(budget_is_positive)
    with pytest.raises(ValueError, match="unknown artefact"):
        catalogue.check("EL-R98", artefacts=("nope",))


def test_the_context_gives_the_input_size_from_the_readouts_or_the_default_disc():
    new = pd.DataFrame({"fault": ["boom", ""], "width": [None, 1280], "height": [None, 720],
                        "default_x": [None, 1.0], "default_y": [None, 1.0], "default_r": [None, 1.0]})
    assert rq.CheckContext("run", {}, images=new).input_size == (1280, 720)
    old = pd.DataFrame({"fault": [""], "default_x": [640.0], "default_y": [680.0], "default_r": [40.0]})
    assert rq.CheckContext("run", {}, images=old).input_size == (1280, 720)
    assert rq.CheckContext("run", {}, images=old.assign(fault="x")).input_size is None
    with pytest.raises(ValueError, match="work_dir"):
        _ = rq.CheckContext("run", {}).work_dir
