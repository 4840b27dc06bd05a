"""Fault-injection cases of the certification basis and the model pin (rows ``T18``..``T20``, ``T22``..``T24``): an
applicant who declares a road safe, loosens the targets to 0.999, swaps an ONNX network's external weights after
pinning or after the run, points them out of the model's folder (at the auditor's key), or flies the shipped
network as its plain ONNX export (once a way to fly it with no frame gate). A deviation fails the evidence gate,
naming it (the auditor may accept one only at its value); a swapped or escaping weights file is refused naming it;
the shipped export keeps the shipped gate, which sends a photograph to the default action.

Rows ``T40``..``T44``: what judged the run is pinned and the basis owns the hazard categories. A label set file
swapped back after the run (flown with road safe) is a gate problem naming it; road declared safe as
``bare_ground`` is the deviation ``class:road``; a Cyrillic look-alike of road is refused; an acceptance binds the
value (0.06 does not accept 0.999) and a plain name is refused.
"""

from __future__ import annotations

from pathlib import Path

from assurance.fault_injection.case import Case, first_image, prepare
from assurance.fault_injection.trust import _evidence, _system
from el.classes.labels import UAVID
from el.segmentation.onnx_engine import SHIPPED_DIR, have_onnxruntime, read_onnx


def _road_safe(ws: Path) -> list[str]:
    """A label set declaring UAVid's road safe (hazard score 0): flown, it would land on roads."""
    import yaml

    doc = UAVID.to_dict()
    road = next(c for c in doc["classes"] if c["name"] == "road")
    road.update(forbidden=False, hazard_score=0.0)
    labels = ws / "labels-road-safe.yaml"
    labels.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    system = _system(ws, "sys-road-safe", f'[labels]\nfile = "{labels.name}"\n')
    return _evidence(ws, "road-safe", "--system", system)


def _loose_targets(ws: Path) -> list[str]:
    """Targets loosened to an unsafe-landing bound of 0.999 at confidence 0.5 on 1 image per perturbation."""
    system = _system(ws, "sys-loose", "[targets]\nunsafe_landing_bound = 0.999\nconfidence = 0.5\n"
                                      "min_images_per_perturbation = 1\n")
    return _evidence(ws, "loose-targets", "--system", system)


def _external_net(ws: Path, name: str, location: str = "weights.bin") -> Path:
    """``WS/NAME/net.onnx``: a 1x1-convolution network on UAVid's classes whose weights lie in ``location``."""
    import io
    import warnings

    import onnx
    import torch

    folder = ws / name
    folder.mkdir(exist_ok=True)
    path = folder / "net.onnx"
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, UAVID.num_classes, 1)).eval()
    buf = io.BytesIO()
    with warnings.catch_warnings():  # the exporter's notices about its own future
        warnings.simplefilter("ignore")
        torch.onnx.export(net, (torch.rand(1, 3, 16, 16),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {2: "h", 3: "w"}}, opset_version=17, dynamo=False)
    onnx.save_model(onnx.load_from_string(buf.getvalue()), str(path), save_as_external_data=True,
                    all_tensors_to_one_file=True, location=location, size_threshold=0)
    return path


def _onnx_system(ws: Path, name: str, path: Path, pin: str | None) -> Path:
    names = ", ".join(f'"{n}"' for n in UAVID.names)
    sha = f'sha256 = "{pin}"\n' if pin else ""
    return _system(ws, name, f'[model]\npath = "{path}"\n{sha}[model.onnx]\nclass_names = [{names}]\n')


def _flip_first_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[0] ^= 0xFF
    path.write_bytes(bytes(data))


def _swapped_external_weights(ws: Path) -> list[str]:
    """An ONNX network whose weights live in ``weights.bin`` beside it, pinned by the system file, then swapped."""
    path = _external_net(ws, "external-net")
    pin = read_onnx(path).sha256
    _flip_first_byte(path.parent / "weights.bin")  # the swap, after pinning: the .onnx file itself is unchanged
    system = _onnx_system(ws, "sys-swapped", path, pin)
    return ["land", str(first_image(ws)), "--monitor", "lhd", "--system", str(system)]


def _external_outside_folder(ws: Path) -> list[str]:
    """An ONNX network whose external data location climbs out of its folder to the auditor's signing key."""
    key = ws / "sign.key"  # the auditor's signing key, by a name as long as the location it replaces
    key.write_bytes(b"-----BEGIN PRIVATE KEY-----\nstand-in\n-----END PRIVATE KEY-----\n")
    path = _external_net(ws, "escaping-net", location="weights.bin")
    raw = path.read_bytes().replace(b"weights.bin", b"../" + key.name.encode(), 1)  # same length: 11 bytes
    path.write_bytes(raw)
    return ["land", str(first_image(ws)), "--monitor", "lhd", "--system", str(_onnx_system(ws, "sys-escape", path,
                                                                                           None))]


def _external_swapped_after_run(ws: Path) -> list[str]:
    """A campaign flown on an ONNX network with external weights, whose ``weights.bin`` is swapped after the run."""
    path = _external_net(ws, "after-run-net")
    system = _onnx_system(ws, "sys-after-run", path, None)
    run = ws / "run-onnx-external"
    if not (run / "manifest.json").exists():
        prepare(["campaign", "--data", ws / "data", "--out", run, "--system", system, "--perturbations", "none",
                 "--monitors", "lhd", "--images", "2", "--quiet"])
        _flip_first_byte(path.parent / "weights.bin")
    return _evidence(ws, "after-run", "--system", system, run=run)


def _shipped_export_on_photo(ws: Path) -> list[str]:
    """The shipped network's packaged ONNX export named as a system file's ``[model]`` (no gate named), flown on a
    blurred-noise "photograph" far from the scenes the network knows: the shipped frame gate must still fly."""
    import cv2
    import numpy as np

    photo = ws / "photograph.png"
    rng = np.random.default_rng(0)
    cv2.imwrite(str(photo), cv2.GaussianBlur((rng.random((180, 320, 3)) * 255).astype(np.uint8), (0, 0), 3))
    system = _system(ws, "sys-shipped-onnx", f'[model]\npath = "{SHIPPED_DIR / "model.onnx"}"\n')
    return ["land", str(photo), "--system", str(system)]


def _uavid_doc(**road: object) -> dict:
    """UAVid's label set as a document, its road updated with ``road``."""
    doc = UAVID.to_dict()
    next(c for c in doc["classes"] if c["name"] == "road").update(road)
    return doc


def _write_labels(path: Path, doc: dict) -> Path:
    import yaml

    path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return path


def _label_set_swapped_back(ws: Path) -> list[str]:
    """A campaign flown with a label set file declaring road safe (the tiny network's classes mapped onto it one to
    one), the honest file put back under the same name after the run: the readouts were judged with road safe."""
    labels = ws / "labels-pinned.yaml"
    names = ", ".join(f'{n} = "{n}"' for n in UAVID.names)
    system = _system(ws, "sys-label-pin", f'[model]\npath = "tiny.pt"\nclass_map = {{ {names} }}\n'
                                          f'[labels]\nfile = "{labels.name}"\n')
    run = ws / "run-label-pin"
    if not (run / "manifest.json").exists():
        _write_labels(labels, _uavid_doc(forbidden=False, hazard_score=0.0))
        prepare(["campaign", "--data", ws / "data", "--out", run, "--system", system, "--perturbations", "none",
                 "--monitors", "lhd", "--images", "2", "--quiet"])
    _write_labels(labels, _uavid_doc())  # the honest file, back under the same name
    return _evidence(ws, "label-pin", "--system", system, run=run)


def _road_safe_bare_ground(ws: Path) -> list[str]:
    """UAVid's road declared safe with the hazard category ``bare_ground`` (once a way past the basis)."""
    labels = _write_labels(ws / "labels-road-bare.yaml", _uavid_doc(forbidden=False, hazard_score=0.0,
                                                                     category="bare_ground"))
    return _evidence(ws, "road-bare", "--system", _system(ws, "sys-road-bare", f'[labels]\nfile = "{labels.name}"\n'))


def _lookalike_road(ws: Path) -> list[str]:
    """A Latin ``road`` (forbidden, a colour no pixel has) beside a Cyrillic look-alike ``r\u043ead`` that owns road's
    colour and is declared safe: the first page would read "road (road): forbidden"."""
    doc = _uavid_doc(rgb=[1, 2, 3])
    doc["classes"].append({"id": len(doc["classes"]), "name": "r\u043ead", "rgb": [128, 64, 128], "forbidden": False,
                           "hazard_score": 0.0, "category": "bare_ground"})
    labels = _write_labels(ws / "labels-lookalike.yaml", doc)
    return _evidence(ws, "lookalike", "--system", _system(ws, "sys-lookalike", f'[labels]\nfile = "{labels.name}"\n'))


def _loose_bound(ws: Path, name: str, *accept: str) -> list[str]:
    """An unsafe-landing bound loosened to 0.999, with the auditor's ``--accept-deviation`` options ``accept``."""
    system = _system(ws, f"sys-{name}", "[targets]\nunsafe_landing_bound = 0.999\n")
    return _evidence(ws, name, "--system", system, *(a for v in accept for a in ("--accept-deviation", v)))


def onnxruntime_available() -> bool:
    """Whether ONNX Runtime can be imported (the shipped network's export can run)."""
    return have_onnxruntime()


def onnx_export_available() -> bool:
    """Whether this installation can export and read ONNX (the ``onnx`` extra)."""
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


BASIS_CASES: tuple[Case, ...] = (
    Case("T18-road-declared-safe", "a system file whose label set declares UAVid's road safe", _road_safe, 1,
         "class:road"),
    Case("T19-targets-loosened", "a system file loosening the unsafe-landing bound to 0.999 at confidence 0.5",
         _loose_targets, 1, "unsafe_landing_bound = 0.999 is looser than the basis's 0.05"),
    Case("T40-label-set-swapped-back", "a campaign flown with a label set declaring road safe, the honest file put "
         "back under its name after the run", _label_set_swapped_back, 1,
         "labels-pinned.yaml: changed since the run was made", pick="gate problem: label set file"),
    Case("T41-road-safe-bare-ground", "UAVid's road declared safe with the hazard category bare_ground",
         _road_safe_bare_ground, 1, "class:road = declared safe with category bare_ground", pick="class:road"),
    Case("T42-lookalike-road-class", "a Cyrillic look-alike 'r\u043ead' owning road's colour, safe, beside a Latin "
         "road", _lookalike_road, 2, "looks like the well-known class name 'road'"),
    Case("T43-accepted-value-mismatch", "--accept-deviation unsafe_landing_bound=0.06 on a bound of 0.999",
         lambda ws: _loose_bound(ws, "accept-mismatch", "unsafe_landing_bound=0.06"), 1,
         "the auditor accepted unsafe_landing_bound=0.06, but the system's value is 0.999",
         pick="unsafe_landing_bound = 0.999"),
    Case("T44-accept-deviation-plain-name", "--accept-deviation unsafe_landing_bound (a name binds no value)",
         lambda ws: _loose_bound(ws, "accept-plain", "unsafe_landing_bound"), 2,
         "--accept-deviation unsafe_landing_bound=0.999"),
    *((Case("T20-swapped-external-weights", "an ONNX network's weights.bin swapped after the system file pinned it",
            _swapped_external_weights, 2, "model.sha256"),
       Case("T23-external-data-outside-folder", "an ONNX network whose external data location is ../ (a key)",
            _external_outside_folder, 2, "leads out of the model file's folder"),
       Case("T24-external-weights-after-run", "an ONNX network's weights.bin swapped after the campaign ran",
            _external_swapped_after_run, 1, "weights.bin: changed since the run was made",
            pick="gate problem")) if onnx_export_available() else ()),
    *((Case("T22-shipped-onnx-no-gate", "the shipped network's own ONNX export as a system's [model], on a photograph",
            _shipped_export_on_photo, 0, "out_of_domain: frame gate", pick="decision:"),)
      if onnxruntime_available() else ()),
)
