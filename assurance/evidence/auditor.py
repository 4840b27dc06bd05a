"""The auditor's part of the evidence report: the hazard log, the safety argument, the ISSRE 2022 metrics, the data
and model records and the AMLAS index, as finished records for the templates and for ``evidence.json``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from assurance.analysis.issre import issre_frame
from assurance.analysis.table import _scenario_order
from assurance.evidence.acceptance import domain_source
from assurance.evidence.amlas import amlas_index, entry
from assurance.evidence.argument import ArgumentInputs, build_argument, check_structure, to_gsn2x, to_yaml
from assurance.evidence.gsn_svg import argument_pages
from assurance.evidence.hazards import hazard_view, load_hazards
from assurance.evidence.model_log import model_log
from assurance.evidence.navigation import anchor, req_anchor
from assurance.evidence.records import data_record, monitor_files
from assurance.evidence.render import rel, write_text
from assurance.evidence.text import ci, fmt
from el.base.hashing import sha256_file
from el.segmentation.weights import card_path

ARGUMENT_FILE = "argument.gsn.yaml"
ISSRE_FILE = "issre.csv"


def issre_view(inp: Any, n_boot: int) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The ISSRE 2022 figures of the run (written to ``issre.csv``): the table's records and the report's rows."""
    cfg = inp.manifest["config"]
    order = [(p, s, m) for p, s in _scenario_order(cfg) for m in cfg["monitors"]]
    frame = issre_frame(inp.images, inp.candidates, n_boot=n_boot, order=order)
    frame.to_csv(inp.out / ISSRE_FILE, index=False, float_format="%.6g")
    rows, last = [], None
    for rec in frame.to_dict("records"):
        scen = f"{rec['perturbation']} (s{int(rec['severity'])})"
        rows.append({"scenario": scen if scen != last else "", "monitor": rec["monitor"],
                     "deployed": rec["monitor"] == inp.deployed, "labelling": rec["labelling"],
                     "counts": f"{rec['tp']} / {rec['fp']} / {rec['tn']} / {rec['fn']}", "n": rec["n"],
                     "cells": [{"v": fmt(rec[k], 3), "ci": ci(rec, k, 3)}
                               for k in ("safety_gain", "residual_hazard", "availability_cost")]})
        last = scen
    return frame.to_dict("records"), rows


def package_entries(inp: Any, record: dict[str, Any]) -> list[dict[str, Any]]:
    """AMLAS index entries of the data and model records, the model and monitor cards and the report's files."""
    def sha(path: Path) -> str:
        return sha256_file(path) if path.is_file() else ""

    out = [entry(r["letter"], f"{r['role']}: {r['name']}", r["path"], r["sha256"])
           for r in record["datasets"] if r["letter"] != "P"]
    failed = any(c["result"] == "fail" for c in record["disjoint"])
    ran = sum(c["result"] != "not checked" for c in record["disjoint"])
    state = "checked" if ran == len(record["disjoint"]) else f"{ran} of {len(record['disjoint'])} checks ran"
    out.append(entry("M", f"Disjointness of the test data from the development data ({state})", "evidence.json "
                     "data_record.disjoint", "", "failed" if failed else ""))
    out.append(entry("Q", "Data-management record", "evidence.json data_record", ""))
    wpath = (inp.manifest.get("weights") or {}).get("path")
    if wpath and card_path(wpath).is_file():
        card = card_path(wpath)
        out += [entry("U", "Model development log: model card and training record", str(rel(card)), sha(card)),
                entry("X", "Internal test results: validation figures of the model card", str(rel(card)), sha(card))]
    used = monitor_files(inp.manifest, inp.registry.parameters.get("calibration_card"))
    for name, letter, what in (("learned.json", "V", "Learned runtime monitor"),
                               ("verifier.json", "V", "Candidate verifier (its ONNX network beside it)"),
                               ("frame_gate.json", "V", "Frame gate (out-of-domain frames)"),
                               ("calibration.json", "X", "Calibration card of the deployed monitor")):
        if name in used:
            out.append(entry(letter, what, str(rel(used[name])), sha(used[name])))
    for name, letter, what in (("junit.xml", "AA", "Verification log: requirement tests (JUnit XML)"),
                               ("faults.csv", "FF", "Integration testing results: fault-injection table")):
        if (inp.out / name).is_file():
            out.append(entry(letter, what, name, sha(inp.out / name)))
    return out


def _sha(rows: list[dict[str, Any]], item: str) -> str:
    return next((r.get("sha256") or "" for r in rows if r["item"] == item), "")


def auditor_context(inp: Any, gate: Any, identity_rows: list[dict[str, Any]], *, n_boot: int = 2000,
                    hazards: str | Path | None = None) -> dict[str, Any]:
    """The auditor's sections of the report (``inp``: the report's ``Inputs``; ``gate``: its ``Gate``); writes the
    argument's gsn2x YAML beside the report."""
    log = load_hazards(hazards, inp.registry)
    card = inp.registry.parameters.get("calibration_card")
    record, mlog = data_record(inp.manifest, inp.facts, card, inp.system), model_log(inp.manifest, card)
    index = amlas_index(identity_rows, [entry("A", "Hazard log", str(rel(log.path)), log.sha256),
                                        *package_entries(inp, record)])
    args = ArgumentInputs(
        registry=inp.registry, hazards=log, results=inp.results,
        waivers={rid: gate.waivers[rid] for rid in gate.waived}, checks=inp.checks,
        hashes={"requirements": _sha(identity_rows, "Requirement test results"),
                "results": _sha(identity_rows, "Results table"), "run": _sha(identity_rows, "Run readouts"),
                "system": _sha(identity_rows, "System file")},
        amlas=index, system=inp.system.name if inp.system is not None else "the embedded default system",
        domain_source=domain_source(inp))
    nodes = build_argument(args)
    problems = check_structure(nodes)
    inp.warnings.extend(f"safety argument: {p}" for p in problems)
    write_text(inp.out / ARGUMENT_FILE, to_yaml(nodes))
    issre, issre_rows = issre_view(inp, n_boot)
    return {"data_record": record, "model_log": mlog,
            "issre": issre, "issre_rows": issre_rows, "issre_file": ISSRE_FILE,
            "hazards": hazard_view(log, gate.states), "hazards_file": log.path.name, "hazards_sha256": log.sha256,
            "argument_pages": argument_pages(nodes, links=argument_links(nodes, inp.registry.ids, log)),
            "argument_problems": problems, "argument_file": ARGUMENT_FILE,
            "argument_counts": _counts(nodes), "argument": to_gsn2x(nodes), "amlas": index}


FIXED_LINKS = {"G-TOP": "#cover", "C-ODD": "#domain", "C-SYS": "#identity", "C-HAZ": "#hazards",
               "J-GATE": "#matrix", "S-ML": "#amlas"}
"""Where the argument's fixed elements link in the report."""


def argument_links(nodes: dict[str, Any], rids: Any, log: Any) -> dict[str, str]:
    """Argument element -> the report's anchor it stands for: a requirement's goal, its waiver and its test
    evidence -> the requirement's row; its campaign-check evidence -> the check; a hazard's goal -> the hazard;
    a strategy -> its page; the AMLAS elements -> the AMLAS index; the context -> its section."""
    reqs, hazards = set(rids), {h.id for h in log.hazards}
    out = dict(FIXED_LINKS)
    for nid, node in nodes.items():
        kind, _, rest = nid.partition("-")
        if nid in out:
            continue
        if node.kind == "Strategy":
            out[nid] = f"#argument-{nid}"
        elif rest.startswith("AMLAS"):
            out[nid] = "#amlas"
        elif kind in ("G", "J") and rest in reqs:
            out[nid] = f"#{req_anchor(rest)}"
        elif kind == "G" and rest in hazards:
            out[nid] = f"#{anchor('haz', rest)}"
        elif kind == "Sn" and rest[:-2] in reqs:
            out[nid] = f"#{anchor('check', rest[:-2])}" if rest.endswith("-C") else f"#{req_anchor(rest[:-2])}"
    return out


def _counts(nodes: dict[str, Any]) -> str:
    kinds: dict[str, int] = {}
    for n in nodes.values():
        kinds[n.kind] = kinds.get(n.kind, 0) + 1
    undeveloped = sum(1 for n in nodes.values() if n.undeveloped)
    plural = {"Strategy": "strategies"}
    return ", ".join(f"{v} {plural.get(k, k.lower() + 's') if v != 1 else k.lower()}" for k, v in kinds.items()) + \
        f"; {undeveloped} undeveloped"


def auditor_document(context: dict[str, Any]) -> dict[str, Any]:
    """The auditor's sections as ``evidence.json`` holds them."""
    return {"hazards": {"file": context["hazards_file"], "sha256": context["hazards_sha256"],
                        "hazards": context["hazards"]},
            "argument": {"file": context["argument_file"], "problems": context["argument_problems"],
                         "elements": context["argument"]},
            "issre": {"file": context["issre_file"], "rows": context["issre"]},
            "data_record": context["data_record"], "model_log": context["model_log"],
            "amlas": [{k: v for k, v in e.items() if k != "cls"} for e in context["amlas"]]}
