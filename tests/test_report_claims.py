"""Every statement of fact in the evidence report is true of the system assessed, checked sentence by sentence on
three systems: (a) the shipped one (the embedded default, on the tiny campaign), (b) a foreign network (ONNX, its own
six classes mapped onto the Semantic Drone set) behind a nadir camera of no declared name, with per-frame poses,
declared ``[odd]`` perturbations and data that carry no scene meta, and (c) a plugin network (``uav_el.models``) on a
label set of the user's own with declared data provenance and licence. Each claim is compared with what the system
file and the run say (the camera geometry's unreachable stripes, the label set, the preset's size, the files the
run used), so a literal about the shipped system said of another fails here."""

from __future__ import annotations

import json
import re
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from helpers import install_distribution

from assurance import cli
from assurance.dataio.uavid import write_sample
from assurance.evidence import generate
from assurance.system import default_system, load_system
from el.classes.labels import UAVID, ids_to_colors, load_label_set

pytest.importorskip("onnxruntime")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
PLUGIN = Path(__file__).parent / "plugins" / "colour_model.py"
SHIPPED_WAIVER = "the segmentation work (mIoU and separation targets)"  # assurance/waivers.yaml's EL-R10


class Page(HTMLParser):
    """The report's visible text: each table row's cells and each paragraph, with the section (or header) it is in."""

    BLOCKS = ("p", "li", "h2", "h3", "div", "summary", "figcaption")

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[tuple[str, list[str]]] = []
        self.blocks: list[tuple[str, str]] = []
        self._sections: list[str] = []
        self._cells: list[str] | None = None
        self._text: list[str] = []
        self._skip = 0

    def handle_starttag(self, tag, attrs):
        if tag in ("section", "header"):
            self._sections.append(dict(attrs).get("id") or "")
        elif tag in ("script", "style"):
            self._skip += 1
        elif tag == "tr":
            self._cells = []
        elif tag in ("td", "th") and self._cells is not None:
            self._cells.append("")
        elif tag in self.BLOCKS:
            self._flush()

    def handle_endtag(self, tag):
        if tag in ("section", "header") and self._sections:
            self._flush()
            self._sections.pop()
        elif tag in ("script", "style"):
            self._skip -= 1
        elif tag == "tr" and self._cells is not None:
            self.rows.append((self.section, [" ".join(c.split()) for c in self._cells]))
            self._cells = None
        elif tag in self.BLOCKS:
            self._flush()

    def handle_data(self, data):
        if self._skip:
            return
        if self._cells:
            self._cells[-1] += data
        elif self._cells is None:
            self._text.append(data)

    @property
    def section(self) -> str:
        return self._sections[-1] if self._sections else ""

    def _flush(self) -> None:
        text = " ".join("".join(self._text).split())
        if text:
            self.blocks.append((self.section, text))
        self._text = []

    def row(self, section: str, name: str) -> str:
        """The value cell of the first row of ``section`` whose first cell is ``name``."""
        found = [cells[1] for sec, cells in self.rows if sec == section and cells and cells[0] == name]
        assert found, f"no row {name!r} in section {section!r}"
        return found[0]

    def text(self, section: str | None = None) -> str:
        return " ".join(t for sec, t in self.blocks if section is None or sec == section)


def read_page(html: Path) -> Page:
    page = Page()
    page.feed(html.read_text("utf-8"))
    page.close()
    return page


def unreachable(system, size: tuple[int, int]) -> int:
    """The system's unreachable stripes at its nominal pose (el.geometry.camera.CameraGeometry)."""
    from assurance.system.system import System

    return System.build(system).core.geometry(*size).unreachable_stripes


# -- the three systems ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def shipped(tiny_campaign, tmp_path_factory):
    """(a) The embedded default system, on the tiny campaign (no requirement results: nothing fails or is waived)."""
    out = tmp_path_factory.mktemp("claims_shipped")
    system = default_system()
    report = generate(tiny_campaign["run"], out, pdf=False, n_boot=20, system=system)
    return {"system": system, "page": read_page(report.html), "doc": json.loads(report.json.read_text()),
            "html": report.html.read_text("utf-8"), "size": (256, 144), "frames": 10}


FLIGHT_POSES = (18.0, 20.0, 22.0)  # the foreign system's test frames' own heights (its flight.csv)


def _foreign_files(root: Path) -> Path:
    """A nadir ONNX system with its own classes, per-frame poses (its test data's from the poses file its [data.test]
    table names, FLIGHT_POSES), [odd] perturbations, and data without scene meta; its training data inside its
    folder, its validation data outside (not read)."""
    from test_onnx_foreign_classes import CLASSES, DRONE, MEAN, STD, TO_DRONE, UNREACHABLE, export

    folder = root / "survey"
    folder.mkdir()
    export(folder / "net.onnx")
    rng = np.random.default_rng(0)
    for split, n in (("train", 1), ("test", 3)):
        for i in range(n):
            ids = np.full((120, 160), DRONE.ids["grass"], np.uint8)
            ids[:, 40 + 20 * i: 60 + 20 * i] = DRONE.ids["paved-area"]
            write_sample(folder / "data" / split, "seq00", f"{i:06d}", (rng.random((120, 160, 3)) * 255).astype(
                np.uint8), ids, labels=DRONE)
        poses = "frame,height_m,pitch_deg\n" + "".join(f"{i:06d},{FLIGHT_POSES[i]},90\n" for i in range(n))
        target = folder / "data" / split / ("flight.csv" if split == "test" else "seq00/poses.csv")
        target.write_text(poses)
    (root / "outside").mkdir()
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    path = folder / "uav-el.toml"
    path.write_text(f'''format = "uav-el-system/1"
[system]
name = "nadir survey"
[labels]
preset = "semantic_drone"
[model]
path = "net.onnx"
class_map = {{ {class_map} }}
unreachable = {json.dumps(UNREACHABLE)}
[model.onnx]
class_names = {json.dumps(CLASSES)}
scaling = "mean_std"
mean = {MEAN}
std = {STD}
[model.provenance]
trained_by = "Example Survey Ltd."
training_data = "data/train"
validation_data = "../outside"
licence = "CC-BY-4.0"
[camera]
sensor_width_mm = 23.5
focal_mm = 16.0
image_width = 160
image_height = 120
height_m = 20.0
pitch_deg = 90.0
poses = "required"
[odd]
height_m = [10.0, 35.0]
pitch_deg = [85.0, 90.0]
perturbations = {{ gaussian_noise = 2 }}
[monitor]
spec = "lhd"
[data.test]
path = "data/test"
layout = "uavid"
poses = "flight.csv"
''')
    return path


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    """(b) Campaign and report run from another folder (relative paths are the system file's, not the working
    directory's); the report takes the run's own system file as its signed manifest records it."""
    root = tmp_path_factory.mktemp("claims_foreign")
    path = _foreign_files(root)
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(elsewhere)
        assert cli.main(["campaign", "--system", str(path), "--out", str(root / "run"), "--perturbations", "none",
                         "gaussian_noise", "--severities", "2", "--monitors", "lhd", "--quiet"]) == 0
        cli.main(["evidence", "--run", str(root / "run"), "--out", str(root / "report"), "--no-pdf", "--boot", "20"])
    return {"system": load_system(path), "page": read_page(root / "report" / "evidence.html"),
            "doc": json.loads((root / "report" / "evidence.json").read_text()), "root": root,
            "html": (root / "report" / "evidence.html").read_text("utf-8"), "size": (160, 120), "frames": 3}


FARM = """name: farm
classes:
  - {id: 0, name: meadow, rgb: [20, 200, 20], forbidden: false, hazard_score: 0.0, category: vegetation}
  - {id: 1, name: hedge, rgb: [0, 90, 40], forbidden: false, hazard_score: 2.0, category: tree}
  - {id: 2, name: track, rgb: [90, 90, 90], forbidden: true, category: road}
  - {id: 3, name: barn, rgb: [200, 30, 30], forbidden: true, category: building}
  - {id: 4, name: tractor, rgb: [30, 30, 200], forbidden: true, category: vehicle}
"""
TO_FARM = {"low_vegetation": "meadow", "tree": "hedge", "road": "track", "building": "barn", "static_car": "tractor",
           "moving_car": "tractor", "clutter": "meadow", "human": "tractor"}


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """(c) A plugin network (``colour``, installed as a distribution) on the user's own label set, an oblique
    camera of its own name, the data's provenance and licence declared."""
    root = tmp_path_factory.mktemp("claims_plugin")
    (root / "labels.yaml").write_text(FARM)
    farm = load_label_set(root / "labels.yaml")
    lut = np.array([farm.names.index(TO_FARM[n]) for n in UAVID.names], np.uint8)
    for i in range(2):
        ids = np.full((144, 256), UAVID.names.index("low_vegetation"), np.uint8)
        ids[:, 60 + 80 * i: 75 + 80 * i] = UAVID.names.index("road")
        ids[:30, 10:60] = UAVID.names.index("building")
        write_sample(root / "data" / "test", "seq00", f"{i:06d}", ids_to_colors(ids), lut[ids], labels=farm)
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_FARM.items())
    path = root / "uav-el.toml"
    path.write_text(f'''format = "uav-el-system/1"
[system]
name = "farm plugin"
[labels]
file = "labels.yaml"
[model]
kind = "plugin"
name = "colour:128"
working_width = 128
classes = {json.dumps(list(UAVID.names))}
class_map = {{ {class_map} }}
[camera]
name = "field-cam"
image_width = 256
image_height = 144
height_m = 40.0
pitch_deg = 35.0
[monitor]
spec = "lhd"
[data]
test = "data/test"
provenance = "flown over the ACME farm in 2025"
licence = "ACME proprietary"
''')
    site = root / "site"
    install_distribution(site, PLUGIN, "uav_el.models", "colour = colour_model:build")
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(str(site))
        mp.chdir(root)
        try:
            assert cli.main(["campaign", "--system", "uav-el.toml", "--out", str(root / "run"), "--perturbations",
                             "none", "--monitors", "lhd", "--quiet"]) == 0
            cli.main(["evidence", "--system", "uav-el.toml", "--run", str(root / "run"), "--out",
                      str(root / "report"), "--no-pdf", "--boot", "20"])
            system = load_system(path)
        finally:
            sys.modules.pop("colour_model", None)
    return {"system": system, "page": read_page(root / "report" / "evidence.html"), "labels": farm,
            "doc": json.loads((root / "report" / "evidence.json").read_text()), "size": (256, 144), "frames": 2,
            "html": (root / "report" / "evidence.html").read_text("utf-8")}


@pytest.fixture(params=["shipped", "foreign", "plugin"])
def case(request):
    return {**request.getfixturevalue(request.param), "name": request.param}


# -- the claims ---------------------------------------------------------------------------------------------------
def test_camera_name_and_view(case):
    from assurance.system import build
    from assurance.system.system import System

    system, page = case["system"], case["page"]
    core = System.build(system).core
    named = build.camera_named(system)
    view = ", nadir view (looking straight down)" if core.pose.pitch_deg >= 80 else ", oblique view"
    cover = page.row("cover", "Camera")
    assert cover.endswith(view) and page.row("domain", "camera") == cover
    assert (f"camera '{core.intrinsics.name}'" in cover) == named
    assert ("of no declared name" in cover) == (not named)
    evaluated = page.row("domain", "Camera")
    assert evaluated.startswith(core.intrinsics.name) and ("name not declared" in evaluated) == (not named)
    assert f"sensor width {core.intrinsics.sensor_width_mm:g} mm" in evaluated
    assert "-custom" not in case["html"]
    if not named:  # a lens of its own without a name is named for what it is
        assert core.intrinsics.name == f"custom (sensor {core.intrinsics.sensor_width_mm:g} mm, focal " \
                                       f"{core.intrinsics.focal_mm:.3g} mm)"


def test_reachable_stripes_follow_the_camera_geometry(case):
    k = unreachable(case["system"], case["size"])
    area = case["page"].row("domain", "Landing area")
    if k:
        assert area.startswith(f"top {k} of 10 image stripes never reachable"), area
    else:
        assert area.startswith("all 10 image stripes reachable"), area
    assert k == {"shipped": 2, "foreign": 0, "plugin": 3}[case["name"]]  # the geometry, not a literal


def test_pose_source(case):
    policy = case["system"].get("camera.poses")
    row = case["page"].row("domain", "Pose source")
    assert f"(pose policy {policy})" in row
    if policy == "required":  # from the poses file the [data.test] table names, not a sequence's poses.csv
        flight = (case["system"].path_of("data.test.path") / "flight.csv").resolve()
        assert f"{case['frames']} frame(s) planned with its own pose from the data's poses file {flight}" in row
    else:
        assert f"{case['frames']} frame(s) planned with the nominal pose" in row


def test_declared_domain_and_perturbations(case):
    system, page = case["system"], case["page"]
    conditions = page.row("domain", "conditions")
    if system.default:
        assert "six perturbations of ICRA22 at severity 3" in conditions
        return
    assert "ICRA22" not in conditions and "daylight" not in conditions
    declared = system.get("odd.perturbations") or {}
    for name, level in declared.items():
        assert f"{name.replace('_', ' ')} up to severity {level}" in conditions
    assert ("as declared in [odd] perturbations" in conditions) == system.sets("odd.perturbations")
    if system.sets("odd.perturbations"):
        assert page.row("domain", f"Perturbation {next(iter(declared))}").startswith("up to severity")


def test_classes_and_categories(case):
    from assurance.requirements.system_facts import forbidden_text
    from assurance.system import build

    labels = build.label_set(case["system"])
    page = case["page"]
    assert page.row("cover", "Forbidden classes") == f"{forbidden_text(labels)} (label set {labels.name})"
    listed = page.row("cover", "Classes and hazard categories")
    for c in labels.classes:
        assert re.search(rf"(^|; ){re.escape(c.name)} \([^)]*\): {'forbidden' if c.forbidden else 'safe'}", listed), c
    if labels != UAVID:
        assert "low_vegetation" not in listed and "road, car or building" not in case["html"]


def _rows(doc: dict, role: str) -> list[dict]:
    return [d for d in doc["data_record"]["datasets"] if d["role"] == role]


def test_provenance_and_licence(case):
    from assurance.evidence.records import LICENCE_SYNTHETIC

    system, doc = case["system"], case["doc"]
    (test,) = _rows(doc, "verification (this campaign)")
    declared = system.get("data.licence")
    assert test["licence"] == (f"{declared} (declared in the system file)" if declared else "not declared")
    provenance = system.get("data.provenance")
    assert test["provenance"] == (f"{provenance} (declared: [data] provenance)" if provenance else "not declared")
    for row in doc["data_record"]["datasets"][1:]:  # development data: the package's own, or declared, or nothing
        if row["record"] in ("model card", "learned.json", "verifier.json", "calibration.json", "frame_gate.json"):
            assert system.default and row["licence"] == LICENCE_SYNTHETIC, row
        else:
            assert row["licence"] == f"{system.get('model.provenance.licence')} (declared in the system file)", row
            assert row["provenance"] == f"trained by {system.get('model.provenance.trained_by')}"
    shown = case["page"].text("data-record") + " ".join(" ".join(c) for s, c in case["page"].rows
                                                         if s == "data-record")
    assert (LICENCE_SYNTHETIC in shown) == system.default  # the generator's licence only where the package's own


def test_disjointness_says_which_checks_ran(case):
    record = case["doc"]["data_record"]
    skipped = [c for c in record["disjoint"] if c["result"] == "not checked"]
    summary = case["page"].text("data-record")
    assert record["summary"] in summary
    assert ("every check ran for this report" in summary) == (not skipped)
    assert "checked for this report)" not in case["html"]
    for c in skipped:
        assert c["check"] in record["summary"] and c["detail"] in record["summary"]
    amlas = [cells for sec, cells in case["page"].rows if sec == "amlas" and "Disjointness" in " ".join(cells)]
    assert amlas and ("(checked)" in " ".join(amlas[0])) == (not skipped)
    if case["system"].sets("model.provenance.training_data"):  # resolved against the system file's folder
        train = case["system"].path_of("model.provenance.training_data")
        ran = [c for c in record["disjoint"] if c["check"] == f"no scene or image shared with {train}"]
        assert ran and ran[0]["result"] == "pass", record["disjoint"]
        outside = case["system"].path_of("model.provenance.validation_data")
        (left,) = [c for c in skipped if str(outside) in c["check"]]
        assert "outside the system file's folder" in left["detail"]


def test_run_size_and_deciding_command(case):
    from assurance.campaign.presets import preset_config

    page, system = case["page"], case["system"]
    cover = page.text("cover")
    release = preset_config("release").images
    assert f"It has {case['frames']} scene(s) per perturbation" in cover
    assert (f"the release run has {release}" in cover) == system.default
    assert ("make release-evidence" in cover) == system.default
    if not system.default:
        assert re.search(r"uav-el campaign --system \S*uav-el\.toml --out ", cover), cover


def _scope(cover: str) -> tuple[str, str]:
    """The cover's run-size note: the requirements it calls undecidable at this size ("" when it says none is), and
    the deciding command."""
    undecided = re.search(r"leaves these requirements not verified: (.*?)\. The registry declares", cover)
    command = re.search(r"decides every requirement on the deployed system: (.*?) \(", cover)
    assert command and (undecided or "its size left no requirement undecided here" in cover), cover
    assert "not verified: none" not in cover
    return undecided.group(1) if undecided else "", command.group(1)


def test_the_deciding_command_and_what_no_run_size_decides(case):
    """A new run folder (a campaign into this one would resume it and refuse another configuration); a requirement
    whose check lacks a calibration card is not 'undecidable at this size': a card decides it."""
    page, system, doc = case["page"], case["system"], case["doc"]
    cover = page.text("cover")
    undecided, command = _scope(cover)
    card = doc["parameters"].get("calibration_card")
    assert ("EL-R16" in undecided) == bool(card), undecided
    assert ("EL-R16 is left not verified at any run size: a calibration card decides it (uav-el calibrate" in cover) \
        == (not card)
    if not system.default:
        out = re.search(r"--out (\S+)", command)
        assert out and out.group(1).endswith("-full"), command
        assert "at least 59 frames per perturbation" in cover  # the bound's images, not the release preset's 70


def test_decisive_run_size_is_the_bounds_for_another_system(foreign, shipped):
    from types import SimpleNamespace

    from assurance import requirements as rq
    from assurance.campaign.presets import preset_config
    from assurance.evidence.context import decisive_images

    reg = rq.load_registry()
    assert decisive_images(SimpleNamespace(system=foreign["system"], registry=reg)) == rq.images_needed(0.05, 0.95)
    assert decisive_images(SimpleNamespace(system=shipped["system"], registry=reg)) == preset_config("release").images


def test_reproduce_keeps_the_data_table(case):
    """The campaign command reads the run's [data] test table (layout, split, poses), not its bare folder."""
    campaign = next(t for s, t in case["page"].blocks if s == "reproduce" and t.startswith("uav-el campaign"))
    campaign = campaign.split("uav-el verify")[0]
    assert ("--data" in campaign) == (case["name"] != "foreign"), campaign  # foreign: a [data.test] table


def test_frame_gate_shows_the_files_sha256(tmp_path):
    """One hash per file: the gate file's SHA-256 (as the AMLAS index shows it), or the record's body hash said so."""
    from assurance.evidence.facts import frame_gate_text
    from el.base.hashing import sha256_file
    from el.base.records import body_sha256

    body = {"kind": "mahalanobis", "features": {"tap": "output"}}
    path = tmp_path / "gate.json"
    path.write_text(json.dumps({"format": "uav-el-frame-gate/1", "body": body, "sha256": body_sha256(body)}))
    text = frame_gate_text({"gate": {"path": str(path), "sha256": body_sha256(body)}})
    assert f"(SHA-256 {sha256_file(path)[:16]})" in text and body_sha256(body)[:16] not in text
    changed = frame_gate_text({"gate": {"path": str(path), "sha256": "0" * 64}})
    assert f"record body SHA-256 {'0' * 16}" in changed and sha256_file(path)[:16] not in changed


def test_pose_texts_follow_the_frames_own_poses(case):
    page = case["page"]
    height, pitch = page.row("domain", "Height"), page.row("domain", "Pitch")
    odd = {cells[0]: cells for sec, cells in page.rows if sec == "domain" and len(cells) == 3}
    limits = page.text("limitations")
    if case["name"] == "foreign":  # planned with each frame's own pose, from its flight.csv
        lo, hi = min(FLIGHT_POSES), max(FLIGHT_POSES)
        assert height.startswith(f"{lo:g} to {hi:g} m (each frame's own pose, from the data's poses file ")
        assert "nominal" not in height and "flight.csv" in pitch
        assert "around each frame's own pose" in odd["Height"][2] and "around the nominal" not in odd["Height"][2]
        assert odd["Pitch"][2].endswith("to 90 deg over the evaluated frames"), odd["Pitch"]  # never past nadir
        assert "a known pose per frame" in limits and "known nominal pose" not in limits
    else:
        assert "(nominal; errors up to" in height and "a known nominal pose" in limits
    for cells in odd.values():
        assert not re.search(r"to (9[1-9]|1[0-9]{2})(\.\d+)? deg", cells[2]), cells


def test_the_ml_argument_names_the_deployed_monitor(case):
    html = case["html"]
    deployed = case["doc"]["parameters"]["deployed_monitor"]
    if deployed.startswith("learned"):
        assert "segmentation network and learned runtime monitor" in html
    elif deployed.startswith("verifier:fuse=learned"):  # the shipped system's
        assert "segmentation network and candidate verifier fused with the learned runtime monitor" in html
    else:
        assert "learned runtime monitor" not in html
        assert f"segmentation network and deployed runtime monitor {deployed.split(':')[0]}" in html


def test_packaged_texts_say_nothing_of_the_shipped_system(case):
    html, page = case["html"], case["page"]
    assert "(the perturbations of ICRA22)" not in html and "0 unsafe landings in 70 images" not in html
    if not case["system"].default:
        assert "ICRA22 at severity" not in html
    assert ("over urban areas" in page.row("domain", "platform")) == case["system"].default
    if not case["system"].default:
        assert "urban" not in page.row("domain", "platform")


def test_messages_count_what_is_short():
    import pandas as pd

    from assurance import requirements as rq
    from assurance.requirements.checks import IMAGES_NEEDED_LEGEND

    images = pd.DataFrame([{"perturbation": "noise", "severity": 3, "key": f"k{i}", "fault": ""} for i in range(8)])
    ev = rq.check_perturbation_coverage(images, ["noise", "fog"], 10)
    assert "noise with 8 evaluated images, fewer than the 10 needed; fog not evaluated" in ev.summary, ev.summary
    table = pd.DataFrame([{"monitor": "lhd", "perturbation": "noise", "severity": 3, "images": 8, "g_star": 0.1,
                           "g_star_lo95": 0.05, "g_star_hi95": 0.2, "unsafe_landing_rate": 0.75},
                          {"monitor": "lhd", "perturbation": "none", "severity": 3, "images": 12, "g_star": 0.1,
                           "g_star_lo95": float("nan"), "g_star_hi95": float("nan"), "unsafe_landing_rate": 0.75}])
    ev = rq.check_safety_gain(table, "lhd", ["noise"], 10)
    assert "noise (s3) with 8 images, fewer than the 10 needed" in ev.summary
    assert "none (s3) has no G* interval" in ev.summary
    ev = rq.check_unsafe_landing_bound(table, "lhd", 0.05, ["noise"], 0.95)
    verdict, legend = ev.summary.split("\n")
    assert ev.status == rq.FAIL and "images_needed" not in verdict and legend == IMAGES_NEEDED_LEGEND


def test_waivers(case):
    system, page = case["system"], case["page"]
    row = page.row("cover", "Waivers")
    if system.default:
        assert row == "assurance/waivers.yaml (the shipped system's)"
    else:
        assert row.startswith("none") and SHIPPED_WAIVER not in case["html"]
        assert case["doc"]["gate"]["waived"] == {}


def test_monitor_files_are_the_runs(case):
    html, doc = case["html"], case["doc"]
    used = {a["path"] for a in doc["amlas"]}
    if case["system"].default:  # the registry's calibration card judges the shipped monitor
        assert "el/monitors/data/calibration.json" in used
    else:
        assert "el/monitors/data" not in html and "learned.json" not in html and "frame_gate.json" not in html
        assert "verifier.json" not in html
    assert "trunk statistics" not in html
    assert case["page"].row("cover", "Frame gate").startswith("none: ")  # none of these runs deployed a gate


# -- claims checked on their own: the gate's problems, a gate file's features, the data's generator, help texts --
def test_deviations_are_not_called_integrity_problems():
    from assurance.evidence.gate import DEVIATION, decide_gate

    problems = [f"{DEVIATION}: unsafe_landing_bound = 0.1 is looser than the basis's 0.05: not accepted"]
    gate = decide_gate({}, problems, None, False)
    assert gate.text.startswith("1 deviation(s) from the certification basis not accepted (below)")
    assert "integrity" not in gate.text
    gate = decide_gate({}, [*problems, "results.json: not bound to a run"], None, False)
    assert gate.text.startswith("1 deviation(s) from the certification basis not accepted and 1 integrity "
                                "problem(s) (below)")


def test_the_frame_gate_is_what_its_file_says():
    from assurance.evidence.model_log import monitor_rows
    from el.monitors.gates.features import WHAT

    for tap in ("output", "pooled", "energy"):
        (row,) = monitor_rows({"frame_gate.json": {"kind": "mahalanobis", "features": {"tap": tap},
                                                   "quantile": 0.997}})
        assert row["value"].startswith(f"mahalanobis on {WHAT[tap]};"), row
    assert "trunk" not in WHAT["output"]


def test_generated_scenes_carry_their_generators_licence(tmp_path):
    from assurance.evidence.records import LICENCE_SYNTHETIC, licence_of

    ours = [{"generator": "assurance.scenes", "version": "1.1", "seed": 2_000_001}]
    assert licence_of(ours, None) == LICENCE_SYNTHETIC
    assert licence_of([{"generator": "someone else's"}], None) == "not declared"
    assert licence_of([], None) == "not declared"
    assert licence_of(ours, "CC0") == "CC0 (declared in the system file)"


def test_help_texts_name_the_systems_defaults():
    import argparse

    from assurance.cli import fit_monitor
    from assurance.cli.arguments import model_option

    p = argparse.ArgumentParser()
    model_option(p)
    assert "the shipped model" not in p.format_help() and "[model] of the" in " ".join(p.format_help().split())
    p = argparse.ArgumentParser()
    fit_monitor.add_arguments(p)
    text = " ".join(p.format_help().split())
    assert "(default: the system file's [data] val; without one, every 5th scene of --data)" in text


def test_each_fact_says_where_it_comes_from(case):
    """The domain's values are the system's (the registry gives the wording only); the acceptance table puts the
    basis's value beside the one judged, names where that comes from, and marks each deviation of page 1; the
    argument's context names the system too. A fact of the system file attributed to the registry fails here."""
    page, system, doc = case["page"], case["system"], case["doc"]
    domain = page.text("domain")
    assert "As declared in the requirement registry" not in case["html"]
    whose = "the embedded default system" if system.default else "the system file"
    assert f"The values are those of {whose}" in domain, domain
    rows = {cells[0]: cells for sec, cells in page.rows if sec == "domain" and len(cells) == 5
            and cells[0] != "parameter"}
    params, basis = doc["parameters"], doc["basis"]["deviations"]
    assert {name.replace(" ", "_") for name in rows} == set(params)
    from assurance.requirements.registry import load_registry

    defaults = load_registry().defaults
    from assurance.evidence.acceptance import SYSTEM_OWN, parameter_text

    for name, (_, base, _judged, source, _mark) in rows.items():
        key = name.replace(" ", "_")
        if key in SYSTEM_OWN and not system.default:  # the shipped system's own file is no basis for another
            assert "the system's own" in base and "el/monitors" not in base, rows[name]
        else:
            assert base == ("not set" if defaults.get(key) is None else parameter_text(defaults[key])), rows[name]
        if params[key] != defaults.get(key):  # the system's own value: never said to be the registry's
            assert source != "the registry (basis)", rows[name]
        if "[targets]" in source:  # said to be the file's [targets] only where the file sets it there
            assert system.sets(f"targets.{key}"), rows[name]
    if system.sets("monitor.spec"):
        assert rows["deployed monitor"][3].endswith("[monitor] spec"), rows["deployed monitor"]
        assert "no looser" not in rows["deployed monitor"][4]  # a choice of monitor is no bound
    for d in basis:
        if d["name"] in params:
            assert rows[d["name"].replace("_", " ")][4].startswith("deviation"), d
    argument = (Path(doc["files"]["html"]).parent / "argument.gsn.yaml") if doc["files"]["html"] else None
    if argument is not None and argument.is_file():
        text = argument.read_text("utf-8")
        assert f"Declared operating domain ({whose}" in text, text[:400]
