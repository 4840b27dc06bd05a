"""Exporting a project network to ONNX, checked against torch (``uav-el export-onnx``).

The exported graph's **input contract** is the project's: one input ``rgb``, float32, NCHW, RGB values in
[0, 1], dynamic batch, height and width (any H, W >= 16: frames and HD patches of any size); one output
``logits`` (B, C, H, W), C the network's label set's classes in label-id order. Networks split into a trunk
and a head (``TrunkHeadNet``: both shipped architectures) are exported through a wrapper that pads the
input to a multiple of the network's stride and crops the logits back with shape operations, so the graph
stays valid at every size (the networks' own Python-int padding would be frozen by the tracer). The
contract (:class:`el.segmentation.onnx_model.OnnxContract`), the label set, the opset and the source weights'
SHA-256 go into the ONNX ``metadata_props``: the file loads with ``load_onnx_model(path)`` and nothing else.
Such a network's trunk (the deterministic part MC dropout shares) is exported too, as further outputs
``trunk.<field>.<i>`` after ``logits`` (:func:`el.segmentation.onnx_engine.flatten_features`), so one ONNX
Runtime pass on a patch gives its softmax and the features MC dropout's head runs on.

After export the file is run under ONNX Runtime on a frame (a rendered synthetic scene at 1024x576 unless
one is given) and on an odd-sized patch, and compared with torch: the largest logit difference is reported,
and the export is refused unless the argmax is identical on every pixel whose torch top-two logit gap
exceeds :data:`TIE_GAP` (a float tie may go either way) and the difference stays below :data:`MAX_DIFF`.
"""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from assurance.files import atomic_write_bytes
from assurance.scenes.generate import generate_scene
from el.base.hashing import sha256_bytes
from el.geometry.camera import working_size
from el.segmentation.factory import load_model
from el.segmentation.inference import Segmenter
from el.segmentation.onnx_engine import engine_record, flatten_features, open_session, record_path
from el.segmentation.onnx_model import META_CONTRACT, META_LABELS, META_OPSET, META_SOURCE, OnnxContract

DEFAULT_OPSET = 17
TIE_GAP = 1e-4
MAX_DIFF = 1e-3
PATCH_SIZE = (131, 77)  # (W, H) of the odd-sized check patch: exercises the padding and the crop


def _wrapped(module: Any) -> Any:
    """The module to trace: a trunk/head network behind shape-op padding and cropping, any other as it is."""
    import torch
    import torch.nn.functional as F

    if not all(callable(getattr(module, a, None)) for a in ("trunk", "head")) or getattr(module, "stride", 1) <= 1:
        return module

    class PadCrop(torch.nn.Module):
        def __init__(self, net: Any) -> None:
            super().__init__()
            self.net, self.stride = net, int(net.stride)

        def forward(self, x: Any) -> Any:
            h, w = x.shape[2], x.shape[3]
            ph, pw = (self.stride - h % self.stride) % self.stride, (self.stride - w % self.stride) % self.stride
            features = self.net.trunk(F.pad(x, (0, pw, 0, ph), mode="replicate"))
            logits = self.net.head(features, crop=False)
            return (logits[:, :, :h, :w], *flatten_features(features)[1])

    return PadCrop(module).eval()


def trunk_output_names(module: Any) -> list[str]:
    """Names of the trunk outputs the export adds after ``logits`` (none for a network without a trunk)."""
    import torch

    if _wrapped(module) is module:
        return []
    with torch.no_grad():
        names, _ = flatten_features(module.trunk(torch.zeros(1, 3, 2 * module.stride, 2 * module.stride)))
    return names


def _as_segmenter(model: Any) -> Segmenter:
    seg = model if isinstance(model, Segmenter) else load_model(model)
    if not isinstance(seg, Segmenter):
        raise ValueError(f"model {model!r} is not a project torch network (a .pt with its card, or the shipped one)")
    return seg


def _onnx_bytes(seg: Segmenter, opset: int, meta: dict[str, str]) -> bytes:
    import onnx
    import torch

    stride = int(getattr(seg.model, "stride", 1))
    example = torch.rand(1, 3, 2 * max(stride, 32), 3 * max(stride, 32), generator=torch.Generator().manual_seed(0))
    buf = io.BytesIO()
    dims = {0: "batch", 2: "height", 3: "width"}
    with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tracer's notes on the networks' own Python-int padding (bypassed)
        outputs = ["logits", *trunk_output_names(seg.model)]
        torch.onnx.export(_wrapped(seg.model.eval()), (example,), buf, input_names=["rgb"], output_names=outputs,
                          dynamic_axes={"rgb": dims, "logits": dims, **{n: {0: "batch", 2: f"{n}.h", 3: f"{n}.w"}
                                                                        for n in outputs[1:]}},
                          opset_version=opset, dynamo=False)
    proto = onnx.load_from_string(buf.getvalue())
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto)
    return proto.SerializeToString()


def _compare(seg: Segmenter, session: Any, image: np.ndarray) -> dict[str, Any]:
    """Torch and ONNX Runtime logits of one RGB uint8 image: largest difference, argmax mismatches."""
    import torch

    x = np.ascontiguousarray((image.astype(np.float32) / np.float32(255.0)).transpose(2, 0, 1)[None])
    with torch.inference_mode():
        ref = seg.model(torch.from_numpy(x)).float().numpy()
    out = session.run(["logits"], {session.get_inputs()[0].name: x})[0]
    if out.shape != ref.shape:
        raise ValueError(f"ONNX output {out.shape} differs from torch's {ref.shape}")
    top2 = np.sort(ref[0], axis=0)[-2:]
    differ = out[0].argmax(0) != ref[0].argmax(0)
    not_tie = differ & (top2[1] - top2[0] > TIE_GAP)
    return {"size": [int(image.shape[1]), int(image.shape[0])], "max_logit_diff": float(np.abs(out - ref).max()),
            "argmax_differ": int(differ.sum()), "argmax_differ_not_tie": int(not_tie.sum()), "pixels": int(differ.size)}


def check_frame(frame: np.ndarray | None, working_width: int) -> np.ndarray:
    """The check frame at the working resolution: the one given, or a rendered synthetic scene (seed 1)."""
    import cv2

    if frame is None:
        frame = generate_scene(1, size=(working_width, working_size(16 * 64, 9 * 64, working_width)[1])).image
    w, h = working_size(frame.shape[1], frame.shape[0], working_width)
    return frame if frame.shape[:2] == (h, w) else cv2.resize(frame, (w, h), interpolation=cv2.INTER_AREA)


def export_onnx(model: Any, out_path: str | Path, *, opset: int = DEFAULT_OPSET, frame: np.ndarray | None = None,
                beside: bool = False) -> dict[str, Any]:
    """Export a project network (a ``Segmenter``, a spec for ``load_model``: None is the shipped one) to ONNX.

    Writes ``out_path`` atomically and returns ``{path, sha256, opset, source_weights_sha256, contract,
    checks: [frame, patch]}`` (see the module docstring). ``beside``: also write the engine record
    ``NAME.onnx.json`` binding the file to the weights (what makes ``Segmenter.load`` run it under ONNX
    Runtime; ``out_path`` must then be the weights file's name with ``.onnx``). A ValueError when the check
    fails (nothing written).
    """
    if isinstance(opset, bool) or not isinstance(opset, int) or not 13 <= opset <= 21:
        raise ValueError(f"opset must be an integer in 13..21, got {opset!r}")
    seg = _as_segmenter(model)
    source = seg.weights_sha256
    contract = OnnxContract(class_names=seg.labels.names)
    meta = {META_CONTRACT: json.dumps(contract.to_dict(), sort_keys=True),
            META_LABELS: json.dumps(seg.labels.to_dict(), sort_keys=True), META_OPSET: str(opset),
            META_SOURCE: source or ""}
    data = _onnx_bytes(seg, opset, meta)
    session = open_session(data, out_path, None)
    frame_rgb = check_frame(frame, seg.working_width)
    patch = np.ascontiguousarray(frame_rgb[: PATCH_SIZE[1], : PATCH_SIZE[0]])
    checks = [_compare(seg, session, frame_rgb), _compare(seg, session, patch)]
    for c in checks:
        if c["argmax_differ_not_tie"] or c["max_logit_diff"] > MAX_DIFF:
            raise ValueError(f"ONNX export differs from torch on a {c['size'][0]}x{c['size'][1]} input: "
                             f"{c['argmax_differ_not_tie']} pixels with another class, largest logit "
                             f"difference {c['max_logit_diff']:.3g} (nothing written)")

    digest = sha256_bytes(data)
    atomic_write_bytes(out_path, data)
    if beside:
        if source is None:
            raise ValueError("--beside needs a network with a weights hash (its card's)")
        atomic_write_bytes(record_path(out_path), (json.dumps(engine_record(source, digest, opset), indent=2)
                                                   + "\n").encode())
    return {"path": str(out_path), "sha256": digest, "opset": opset, "source_weights_sha256": source,
            "contract": contract.to_dict(), "classes": list(seg.labels.names), "checks": checks}
