"""The label set and class hierarchy that judged a run, pinned by content in its signed manifest and re-checked.

Every readout of a campaign is judged with a label set (which classes are forbidden, their hazard scores) and the
CH monitor's class hierarchy. A system file names its label set by path or preset only, so a file swapped back
after the run (flown with road declared safe, the honest file put back under the same name) would leave the
evidence judged on one set and reported on another. The manifest (a subject of the campaign's signed statement,
``assurance.campaign.attestation``) therefore records their content SHA-256 (:func:`label_record`): of the
canonical JSON (``el.base.records.body_sha256``) of the set as flown (``LabelSet.to_dict``: classes, colours, states,
hazard scores, categories, ignore colour, declared tree) and of the tree the CH monitor used
(``el.monitors.hierarchy.default_hierarchy``: nodes and parents), the built-in and packaged sets included.
``uav-el evidence`` recomputes both from the system it judges (:func:`label_problems`): a difference is a gate
problem naming the file.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from assurance.campaign import readouts
from el.base import safeyaml
from el.base.records import body_sha256
from el.classes.labels import PRESET_DIR, LabelSet
from el.monitors.hierarchy import SHIPPED_TREES, default_hierarchy
from el.segmentation.contract import labels_of

PREDICATE_KEYS = ("label_set_sha256", "hierarchy_sha256")
"""What a campaign statement signed by this toolkit carries of the label pin (present, even null, in every statement
it signs: their presence tells a run signed by a toolkit that pins its label set)."""


def label_set_sha256(labels: Any) -> str:
    """SHA-256 of a label set's canonical content (its ``to_dict``, categories included, as sorted-key JSON)."""
    return body_sha256(labels.to_dict())


def hierarchy_sha256(labels: Any) -> str:
    """SHA-256 of the class tree the CH monitor uses with ``labels`` (its nodes and their parents)."""
    try:
        tree = default_hierarchy(labels)
    except ValueError:  # a declared tree the CH monitor refuses (a campaign without CH flies): pinned as declared
        return body_sha256({"declared": labels.to_dict().get("hierarchy")})
    return body_sha256({"nodes": list(tree.nodes), "parents": [int(p) for p in tree.parents]})


def _declared_tree_file(label_file: Path) -> Path | None:
    """The hierarchy file a label set file names (``hierarchy: FILE``, relative to it), if any."""
    try:
        doc = safeyaml.load_file(label_file, what="label set file")
    except Exception:  # noqa: BLE001  (unreadable now: the set itself is named, and loading it says why)
        return None
    ref = doc.get("hierarchy") if isinstance(doc, dict) else None
    return label_file.parent / ref if isinstance(ref, str) else None


def label_sources(labels: Any, system: Any = None) -> tuple[str, str]:
    """How messages name where ``labels`` and its class tree come from (for the system file ``system``): the label
    set file, the packaged preset's file or the built-in set; the tree's file, or the set that declares or implies
    it."""
    file = system.labels_file if system is not None else None
    preset = system.labels_preset if system is not None else None
    if file is not None:
        where = f"label set file {file}"
    elif preset not in (None, "uavid"):
        where = f"label set preset {preset} ({PRESET_DIR / f'{preset}.yaml'})"
    else:
        where = f"built-in label set {labels.name} (el/classes/labels.py)"
    if labels in SHIPPED_TREES:
        tree = f"class hierarchy el/monitors/{SHIPPED_TREES[labels]}"
    elif labels.hierarchy is not None:
        declared = _declared_tree_file(Path(file)) if file is not None else None
        tree = (f"class hierarchy file {declared}" if declared is not None
                else f"class hierarchy declared in the {where}")
    else:
        tree = f"class hierarchy derived from the forbidden/safe split of the {where}"
    return where, tree


def label_record(labels: Any, system: Any = None) -> dict[str, Any]:
    """The manifest's ``labels``: the label set's name and content SHA-256, its class tree's, and where each came
    from (``system``: the system file whose ``[labels]`` names it)."""
    where, tree = label_sources(labels, system)
    return {"name": labels.name, "sha256": label_set_sha256(labels), "source": where,
            "hierarchy_sha256": hierarchy_sha256(labels), "hierarchy_source": tree}


def flown_labels(system_file: Any, network: Any) -> dict[str, Any] | None:
    """The ``labels`` record of a campaign: the system file's label set when the network judges with it (equal in
    every class, state, score and colour: its categories are the system's), else the network's own label set (a
    model handed in through the API); None for a network that names only its output classes."""
    judged = labels_of(network)
    if not isinstance(judged, LabelSet):
        return None
    if system_file is not None:

        own = system_file.labels()
        if own == judged:
            return label_record(own, system_file)
    return label_record(judged)


def predicate_fields(man: Mapping[str, Any]) -> dict[str, Any]:
    """The label pin as the campaign's signed statement carries it (:data:`PREDICATE_KEYS`)."""
    rec = man.get("labels") or {}
    return {"label_set_sha256": rec.get("sha256"), "hierarchy_sha256": rec.get("hierarchy_sha256")}


def label_problems(system: Any, man: Mapping[str, Any], predicate: Mapping[str, Any] | None, run: Path
                   ) -> tuple[list[str], list[str]]:
    """(gate problems, warnings): the label set or class tree of ``system`` (the system file the report judges)
    that is not the one the run recorded, one line each naming the file and both hashes; a run that pins neither.

    A run without the record was made before the pin. When its statement was signed by a toolkit that pins
    (``predicate`` holds :data:`PREDICATE_KEYS`, verified against the trusted keys), the signer vouched for a run
    whose classes it did not pin (a campaign resumed over an older run, or a manifest written by hand and signed):
    a gate problem. Otherwise (an older toolkit's run, or no keys to tell) it stays readable with a warning: that
    toolkit could not pin it, and failing every earlier run would say nothing about the run itself."""
    if system is None:
        return [], []
    rec = man.get("labels")
    if not isinstance(rec, Mapping) or not rec.get("sha256"):
        text = (f"{run}: the run does not pin its label set and class hierarchy (no content hashes in its manifest): "
                "the classes it was judged with cannot be shown to be the system's")
        signed_new = predicate is not None and all(k in predicate for k in PREDICATE_KEYS)
        return ([text], []) if signed_new else ([], [text + " (a run made before they were pinned)"])

    labels = system.labels()
    where, tree = label_sources(labels, system)
    problems = []
    for kind, what, was, then, now in (
            ("label set", where, rec.get("source"), rec.get("sha256"), label_set_sha256(labels)),
            ("class hierarchy", tree, rec.get("hierarchy_source"), rec.get("hierarchy_sha256"),
             hierarchy_sha256(labels))):
        if then == now:
            continue
        change = "changed since the run was made" if was == what else f"not the {kind} the run was judged with ({was})"
        problems.append(f"{what}: {change} (SHA-256 {str(then)[:12]} then, {now[:12]} now): every readout was judged "
                        f"with the {kind} as it was; re-run the campaign")
    if predicate is not None and any(k in predicate for k in PREDICATE_KEYS) and \
            (predicate.get("label_set_sha256"), predicate.get("hierarchy_sha256")) != \
            (rec.get("sha256"), rec.get("hierarchy_sha256")):
        problems.append(f"{run}: the label pin of the manifest is not the one the campaign's statement signed")
    return problems, []


def check_resumed_labels(run_dir: Path, man: Mapping[str, Any]) -> None:
    """Refuse to resume a run whose manifest pins another label set or class tree than this campaign's
    (``readouts.RunError`` naming both): its earlier shards were judged with other classes."""
    if not (Path(run_dir) / "manifest.json").is_file():
        return
    was, now = readouts.read_manifest(run_dir).get("labels") or {}, man.get("labels") or {}
    for key, what in (("sha256", "label set"), ("hierarchy_sha256", "class hierarchy")):
        if was.get(key) and now.get(key) and was[key] != now[key]:
            raise readouts.RunError(f"{run_dir}: holds a campaign run judged with another {what} ({was.get('source')}, "
                                    f"SHA-256 {was[key][:12]} then; {now[key][:12]} now); use a new --out folder or "
                                    "delete this one")


__all__ = ["PREDICATE_KEYS", "check_resumed_labels", "flown_labels", "hierarchy_sha256", "label_problems",
           "label_record", "label_set_sha256", "label_sources", "predicate_fields"]
