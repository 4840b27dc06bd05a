"""Images and label maps in the UAVid layout, ``ROOT/seqNN/{Images,Labels}/NNNNNN.png`` (a frame: ``el.base.imageio``).

Images cross the API as RGB uint8 arrays (H, W, 3); OpenCV's BGR order stays inside this module.
Every error names the file and the problem, so a command line can print it as one line.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from assurance.dataio.poses import POSES_FILE, sequence_poses
from assurance.files import atomic_write_bytes, public_mode  # noqa: F401  (re-exported)
from el.base.errors import DataError
from el.base.imageio import image_size as header_image_size
from el.base.imageio import read_image
from el.base.rgb import check_rgb
from el.classes.labels import LabelSet
from el.geometry.camera import Pose

IMAGE_DIR = "Images"
LABEL_DIR = "Labels"
META_DIR = "meta"
_SEQ = re.compile(r"^seq\d+$")
_EXTS = (".png", ".jpg", ".jpeg")


def write_image(path: str | Path, rgb: np.ndarray, *, compression: int = 3) -> None:
    """Write an RGB uint8 image atomically (temp file + rename); the format follows the suffix."""
    path = Path(path)
    rgb = np.asarray(rgb)
    check_rgb(rgb, f"{path}: image")
    params = [cv2.IMWRITE_PNG_COMPRESSION, compression] if path.suffix.lower() == ".png" else []
    ok, buf = cv2.imencode(path.suffix or ".png", np.ascontiguousarray(rgb[:, :, ::-1]), params)
    if not ok:
        raise DataError(f"{path}: could not encode image")
    atomic_write_bytes(path, buf.tobytes())


def read_labels(path: str | Path, labels: LabelSet) -> np.ndarray:
    """Read a colour-coded label PNG (``labels``' palette: the system's label set) as class ids (H, W) uint8;
    unknown colours are an error."""
    return labels.colors_to_ids(read_image(path), source=path)


def write_labels(path: str | Path, ids: np.ndarray, labels: LabelSet) -> None:
    """Write class ids (H, W) as a colour-coded label PNG (``labels``' palette)."""
    write_image(path, labels.ids_to_colors(ids))


@dataclass(frozen=True)
class Sample:
    """One image of a dataset and its label file (None when the set is unlabelled), in any layout
    (``assurance.dataio.layouts``).

    ``pose`` and ``roll_deg``: the frame's line of its poses CSV (``poses_path``, None when there is none), read
    when ``iter_samples`` is asked to (``assurance.dataio.poses``). ``label_encoding``: how the label file codes
    classes, ``rgb`` (the label set's palette) or ``ids`` (grey values, class id = value - ``id_offset``), so a
    worker decodes it with the sample alone. ``meta_dir``: where a synthetic scene's meta JSON would lie (None:
    the UAVid layout's ``seqNN/meta``)."""

    sequence: str
    frame: str
    image_path: Path
    label_path: Path | None
    pose: Pose | None = None
    roll_deg: float = 0.0
    poses_path: Path | None = None
    label_encoding: str = "rgb"
    id_offset: int = 0
    meta_dir: Path | None = None

    @property
    def key(self) -> str:
        return f"{self.sequence}/{self.frame}"

    def meta_path(self) -> Path:
        folder = self.meta_dir if self.meta_dir is not None else self.image_path.parent.parent / META_DIR
        return folder / f"{self.frame}.json"


def iter_samples(root: str | Path, *, require_labels: bool = True, check_sizes: bool = False,
                 poses: bool = False) -> Iterator[Sample]:
    """Yield the samples of ``ROOT/seqNN/{Images,Labels}`` in sorted order.

    Raises DataError for a missing root, a root without sequences, an image without its label
    (or a label without its image) and, with ``check_sizes``, an image and label of different sizes.
    With ``poses``, each sequence's ``poses.csv`` (if any) is read into the samples' ``pose``: a
    malformed sidecar, or one naming a frame without an image, is a DataError.
    """
    root = Path(root)
    if not root.is_dir():
        raise DataError(f"{root}: dataset folder not found")
    seqs = sorted(p for p in root.iterdir() if p.is_dir() and _SEQ.match(p.name))
    if not seqs:
        raise DataError(f"{root}: no seqNN folders (expected ROOT/seqNN/{IMAGE_DIR} and ROOT/seqNN/{LABEL_DIR})")
    for seq in seqs:
        img_dir, lab_dir = seq / IMAGE_DIR, seq / LABEL_DIR
        if not img_dir.is_dir():
            raise DataError(f"{img_dir}: missing {IMAGE_DIR} folder")
        images: dict[str, Path] = {}
        for p in sorted(img_dir.iterdir()):
            if p.suffix.lower() not in _EXTS:
                continue
            if p.stem in images:  # 000000.png beside 000000.jpg: which one is the frame?
                raise DataError(f"{p}: a second image of frame {seq.name}/{p.stem} (the first: "
                                f"{images[p.stem].name})")
            images[p.stem] = p
        labels: dict[str, Path] = {}
        if lab_dir.is_dir():
            labels = {p.stem: p for p in lab_dir.iterdir() if p.suffix.lower() == ".png"}
        elif require_labels:
            raise DataError(f"{lab_dir}: missing {LABEL_DIR} folder")
        if require_labels or labels:
            unpaired_img = sorted(set(images) - set(labels))
            unpaired_lab = sorted(set(labels) - set(images))
            if unpaired_img:
                raise DataError(f"{img_dir / unpaired_img[0]}.*: image has no label in {lab_dir}"
                                + (f" ({len(unpaired_img)} unpaired)" if len(unpaired_img) > 1 else ""))
            if unpaired_lab:
                raise DataError(f"{labels[unpaired_lab[0]]}: label has no image in {img_dir}"
                                + (f" ({len(unpaired_lab)} unpaired)" if len(unpaired_lab) > 1 else ""))
        sidecar = sequence_poses(seq, set(images)) if poses else {}
        poses_path = seq / POSES_FILE if poses and (seq / POSES_FILE).is_file() else None
        for frame in sorted(images):
            fp = sidecar.get(frame)
            sample = Sample(seq.name, frame, images[frame], labels.get(frame), fp.pose if fp else None,
                            fp.roll_deg if fp else 0.0, poses_path)
            if check_sizes and sample.label_path is not None:
                check_same_size(sample.image_path, sample.label_path)
            yield sample


def image_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image as read (EXIF orientation applied), from its header without decoding it when
    it has one (PNG, JPEG); DataError above the pixel limit (``el.base.imageio.image_size``)."""
    return header_image_size(path)


def check_same_size(image_path: str | Path, label_path: str | Path) -> None:
    """DataError when an image and its label map differ in size."""
    si, sl = image_size(image_path), image_size(label_path)
    if si != sl:
        raise DataError(f"{label_path}: label size {sl[0]}x{sl[1]} differs from image {image_path} ({si[0]}x{si[1]})")


def sample_paths(root: str | Path, sequence: str, frame: str) -> tuple[Path, Path, Path]:
    """Image, label and meta paths of a sample in the UAVid layout (folders not created)."""
    seq = Path(root) / sequence
    return seq / IMAGE_DIR / f"{frame}.png", seq / LABEL_DIR / f"{frame}.png", seq / META_DIR / f"{frame}.json"


def write_sample(root: str | Path, sequence: str, frame: str, image: np.ndarray, ids: np.ndarray, *,
                 labels: LabelSet) -> Sample:
    """Write an image and its class-id map (``labels``' palette) into the UAVid layout; returns the written sample."""
    if image.shape[:2] != ids.shape:
        raise ValueError(f"image {image.shape[:2]} and labels {ids.shape} differ in size")
    img_path, lab_path, _ = sample_paths(root, sequence, frame)
    write_image(img_path, image)
    write_labels(lab_path, ids, labels)
    return Sample(sequence, frame, img_path, lab_path)
