"""Fault-injection cases of the certification basis and the model pin (rows ``T18``..``T20``, issue 39): an applicant
who declares a road safe, loosens the targets to 0.999, or swaps an ONNX network's external weights after pinning.
The first two fail the evidence gate, naming the deviation (the auditor may accept one only by name); the third is
refused before any frame, naming ``model.sha256``.
"""

from __future__ import annotations

from pathlib import Path

from assurance.fault_injection.case import Case, first_image
from assurance.fault_injection.trust import _evidence, _system


def _road_safe(ws: Path) -> list[str]:
    """A label set declaring UAVid's road safe (hazard score 0): flown, it would land on roads."""
    import yaml

    from el.labels import UAVID

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


def _swapped_external_weights(ws: Path) -> list[str]:
    """An ONNX network whose weights live in ``weights.bin`` beside it, pinned by the system file, then swapped."""
    import io
    import warnings

    import onnx
    import torch

    from el.labels import UAVID
    from el.segmentation.onnx_engine import read_onnx

    folder = ws / "external-net"
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
                    all_tensors_to_one_file=True, location="weights.bin", size_threshold=0)
    pin = read_onnx(path).sha256
    weights = folder / "weights.bin"
    data = bytearray(weights.read_bytes())
    data[0] ^= 0xFF  # the swap, after pinning: the .onnx file itself is unchanged
    weights.write_bytes(bytes(data))
    names = ", ".join(f'"{n}"' for n in UAVID.names)
    system = _system(ws, "sys-swapped", f'[model]\npath = "{path}"\nsha256 = "{pin}"\n[model.onnx]\n'
                                        f"class_names = [{names}]\n")
    return ["land", str(first_image(ws)), "--monitor", "lhd", "--system", str(system)]


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
    *((Case("T20-swapped-external-weights", "an ONNX network's weights.bin swapped after the system file pinned it",
            _swapped_external_weights, 2, "model.sha256"),) if onnx_export_available() else ()),
)
