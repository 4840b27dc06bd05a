"""The data sets of the data-management record read in any layout, and the checks that the test data are disjoint
from the development data (``assurance.evidence.records``): every set's frames are read through the data layouts
(``assurance.dataio.layouts.iter_samples``: a folder's layout detected, a ``[data]``-like table's layout and split
list applied), so a test split and a training split of one folder are compared frame by frame, by image content."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from assurance.dataio.layouts import DataSpec, iter_samples
from assurance.dataio.poses import read_meta
from assurance.evidence.render import ROOT
from assurance.fitting.learned_monitor import split_digest
from assurance.scenes.generate import split_of_seed
from el.base.errors import DataError
from el.base.hashing import sha256_file


def read_frames(source: Any, cache: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The frames of a data set (a folder or a ``DataSpec``): ``samples``, each image's SHA-256 (``images``, in the
    samples' order; empty for a file the bounded reader refuses), the set's ``sha256`` (every image file: relative
    path and SHA-256, as ``uav-el fit-gate`` records a split's) and ``error``, why it could not be read (empty when
    it was). Read once per report (``cache``)."""
    key = json.dumps(spec_of(source), sort_keys=True, default=str)
    if cache is not None and key in cache:
        return cache[key]
    out = _read_frames(source)
    if cache is not None:
        cache[key] = out
    return out


def spec_of(source: Any) -> dict[str, Any]:
    """A data source as data: a spec's keys, or a folder's path alone."""
    return source.to_dict() if isinstance(source, DataSpec) else {"path": str(source)}


def _read_frames(source: Any) -> dict[str, Any]:
    try:
        samples = list(iter_samples(source, require_labels=False))
    except (DataError, OSError, ValueError) as exc:
        return {"samples": [], "images": [], "sha256": "", "error": str(exc)}
    images = []
    for s in samples:
        try:
            images.append(sha256_file(s.image_path))  # bounded: a FIFO, a device or /proc is refused, never read
        except (OSError, ValueError):
            images.append("")
    root = Path(source)
    files = zip((Path(s.image_path).relative_to(root).as_posix() for s in samples), images, strict=True)
    digest = split_digest(files)
    return {"samples": samples, "images": images, "sha256": digest if samples else "", "error": ""}


def frame_metas(samples: list[Any]) -> list[dict[str, Any]]:
    """The scene meta JSON of the samples that have one (this toolkit's scenes), each read bounded
    (``assurance.dataio.poses.read_meta``); none for data without it."""
    out = []
    for s in samples:
        try:
            out.append(read_meta(s.meta_path()))
        except (OSError, ValueError):
            continue
    return out


def seeds_of(metas: list[dict[str, Any]]) -> list[int]:
    """The scene seeds the meta record (a seed that is no integer is passed over)."""
    out = []
    for m in metas:
        try:
            out.append(int(m["seed"]))
        except (KeyError, TypeError, ValueError):
            continue
    return out


def source_of(folder: str | Path, spec: dict[str, Any] | None) -> Any:
    """What to read: the folder (its layout detected), or a ``DataSpec`` of the spec's keys at the folder (the
    folder alone when the keys do not make one)."""
    if not spec:
        return Path(folder)
    try:
        return DataSpec.from_dict({**spec, "path": Path(folder)})
    except (TypeError, ValueError):
        return Path(folder)


def used(items: list[Any], scenes: Any) -> list[Any]:
    """The [first, end) of ``items`` a card says were used (all when it records no such range)."""
    if isinstance(scenes, list) and len(scenes) == 2 and all(isinstance(v, int) for v in scenes):
        return items[scenes[0]:scenes[1]]
    return items


def set_label(row: dict[str, Any]) -> str:
    """How the checks name a development set: its path (else its name), with the split list and the scenes used."""
    spec, scenes = row.get("spec") or {}, row.get("scenes") or []
    parts = ([f"split {spec['split']}"] if spec.get("split") else []) + (
        [f"scenes {scenes[0]}:{scenes[1]}"] if len(scenes) == 2 else [])
    return (row.get("path") or row["name"]) + (f" ({', '.join(parts)})" if parts else "")


def _folder_check(test: dict[str, Any], seeds: list[int], dev: dict[str, Any], scenes: Any,
                  shown: str) -> dict[str, str]:
    """The check that no image (by content) or scene seed of the test data is among the frames of a development set
    that were used (not checked when either cannot be read or holds no image: a pass over no image says nothing)."""
    what = f"no scene or image shared with {shown}"
    test_images = {h for h in test["images"] if h}
    dev_images = {h for h in used(dev["images"], scenes) if h}
    for frames, images, who in ((test, test_images, "the test data"), (dev, dev_images, shown)):
        if frames["error"]:
            return {"check": what, "result": "not checked", "detail": f"{who} could not be read: {frames['error']}"}
        if not images:
            return {"check": what, "result": "not checked", "detail": f"no readable image in {who}"}
    shared = test_images & dev_images
    dev_seeds = set(seeds_of(frame_metas(used(dev["samples"], scenes))))
    common = sorted(dev_seeds & set(seeds))
    counts = f"{len(test_images)} test images, {len(dev_images)} development images"
    seeds_text = (f", {len(common)} common seed(s) ({counts}, {len(dev_seeds)} development scenes)"
                  if seeds or dev_seeds else f" ({counts}; no scene meta, so no seeds to compare)")
    return {"check": what, "result": "fail" if shared or common else "pass",
            "detail": f"{len(shared)} identical image file(s){seeds_text}"}


def disjointness(test_metas: list[dict[str, Any]], test_sha: str, test_source: Any, dev: list[dict[str, Any]],
                 cache: dict[str, dict[str, Any]] | None = None) -> list[dict[str, str]]:
    """Checks that the test data (``test_source``: its folder or ``DataSpec``) shares nothing with the development
    data: seed ranges, data-set hashes, and, where the development data are on this machine, scene seeds and image
    contents, set by set (a split list's frames only). Each check: what, result, detail; one that could not run
    says ``not checked`` and why."""
    cache = {} if cache is None else cache
    checks = []
    seeds = seeds_of(test_metas)
    if seeds:
        wrong = [s for s in seeds if split_of_seed(s) != "test"]
        checks.append({"check": "test scenes' seeds lie in the test split's seed range", "result":
                       "pass" if not wrong else "fail", "detail": f"{len(seeds)} seeds checked" + (
                           f"; outside: {wrong[:5]}" if wrong else "")})
    else:
        checks.append({"check": "test scenes' seeds lie in the test split's seed range", "result": "not checked",
                       "detail": "the test data carry no scene meta, so no seeds"})
    checks.append(_hash_check(test_sha, dev))
    seen: set[str] = set()
    for r in dev:
        shown = set_label(r)
        if shown in seen or not (r["path"] or r.get("unread")):
            continue
        seen.add(shown)
        if r.get("unread"):  # never read: outside the system file's folder, a card's path relative to nothing known
            checks.append({"check": f"no scene or image shared with {shown}", "result": "not checked",
                           "detail": r["unread"]})
            continue
        where = r.get("folder") or r["path"]
        folder = Path(where) if Path(where).is_absolute() else ROOT / where
        test_root = Path(test_source) if test_source is not None else None
        if not folder.is_dir() or test_root is None or not test_root.is_dir():
            missing = shown if not folder.is_dir() else f"the test data folder {test_root}"
            checks.append({"check": f"no scene or image shared with {shown}", "result": "not checked",
                           "detail": f"{missing} is not on this machine"})
            continue
        checks.append(_folder_check(read_frames(test_source, cache), seeds,
                                    read_frames(source_of(folder, r.get("spec")), cache), r.get("scenes"), shown))
    return checks


def _hash_check(test_sha: str, dev: list[dict[str, Any]]) -> dict[str, str]:
    """The check that the test data's hash is none of the development data's (not checked when no development data
    set records a hash: a comparison with nothing shows nothing)."""
    what = "the test data's hash is none of the development data's"
    hashed = [r for r in dev if r["sha256"]]
    if not hashed:
        return {"check": what, "result": "not checked", "detail": "no development data set recorded" if not dev else
                f"none of the {len(dev)} development data set(s) records its hash"}
    same = [r["name"] for r in hashed if r["sha256"] == test_sha]
    return {"check": what, "result": "fail" if same else "pass",
            "detail": f"compared with {len(hashed)} development data set(s)" + (
                f" (of {len(dev)}; the others record no hash)" if len(hashed) < len(dev) else "")
            + (f"; equal: {', '.join(same)}" if same else "")}


def disjoint_summary(checks: list[dict[str, str]]) -> str:
    """What the disjointness checks show, in a line: failed, every one ran and passed, or how many ran and which
    did not (and why)."""
    failed = [c["check"] for c in checks if c["result"] == "fail"]
    skipped = [f"{c['check']} ({c['detail']})" for c in checks if c["result"] == "not checked"]
    ran = len(checks) - len(skipped)
    head = (f"NOT disjoint: failed: {'; '.join(failed)}" if failed else
            "disjoint: every check ran for this report and passed" if not skipped else
            f"{ran} of {len(checks)} checks ran for this report and passed")
    return head + (f"; not checked: {'; '.join(skipped)}" if skipped else "")
