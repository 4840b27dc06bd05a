"""Reading a camera frame from a file as RGB uint8 (H, W, 3); OpenCV's BGR order stays inside this module.

The one file reader of the flight path: every error is a ``DataError`` naming the file and the problem,
which the decision loop turns into the default action. The frame's size is read from its header and
refused above ``max_pixels`` before anything is decoded (a 68-byte file may claim 10^10 pixels), and a
JPEG's EXIF orientation is applied, so the array is the scene as the camera saw it.
"""

from __future__ import annotations

import functools
import hashlib
import threading
from pathlib import Path

import cv2
import numpy as np

from el.base.errors import DataError
from el.base.imageheader import PNG_SIGNATURE, Header, pil_size, read_header

MAX_PIXELS = 7680 * 4320 * 5 // 4
"""Default pixel limit of a frame: an 8K frame (7680 x 4320, 33.2 Mpx) plus a quarter (41.5 Mpx, ~125 MB as
RGB). Larger files are refused from their header; ``PipelineConfig.max_pixels`` and ``--max-pixels`` set it."""
HEADER_BYTES = 1 << 16  # a JPEG's EXIF block (orientation) and frame header mostly lie within the first 64 KiB
MAX_HEADER_BYTES = 1 << 24
"""How far a JPEG's markers are walked for its frame header when its metadata (EXIF with a thumbnail, XMP, an ICC
profile) runs past :data:`HEADER_BYTES` (16 MiB: metadata segments are 64 KiB each)."""


def check_max_pixels(value: object) -> int:
    """A valid pixel limit (a positive integer), else ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"max_pixels must be a positive integer, got {value!r}")
    return int(value)


def read_image(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """Read a colour image as RGB uint8 (H, W, 3), EXIF orientation applied; DataError if missing, not an image,
    truncated, or larger than ``max_pixels`` (checked from the header, before decoding)."""
    return read_image_meta(path, max_pixels=max_pixels)[0]


def read_image_meta(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray, dict[str, int]]:
    """``read_image`` and what the file said about itself: ``{"exif_orientation": n}`` when a JPEG's EXIF
    orientation (n in 2..8) was applied, else ``{}``."""
    path = Path(path)
    header, data = _read_checked(path, max_pixels)
    return _decode_frame(path, header, data)


def read_image_hashed(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray, dict[str, int], str]:
    """``read_image_meta`` and the SHA-256 (hex) of the file's bytes, those it decoded (a decision's
    ``input.sha256``): hashed on another thread while they decode, and with no second read of the file."""
    path = Path(path)
    header, data = _read_checked(path, max_pixels)
    digest: list[str] = []
    hasher = threading.Thread(target=lambda: digest.append(hashlib.sha256(memoryview(data)).hexdigest()), daemon=True)
    hasher.start()
    try:
        rgb, meta = _decode_frame(path, header, data)
    finally:
        hasher.join()
    return rgb, meta, digest[0]


def _read_checked(path: Path, max_pixels: int) -> tuple[Header | None, np.ndarray]:
    """The file's header and bytes, refused (DataError) above ``max_pixels``, when empty or a PNG cut short."""
    header = _checked_header(path, max_pixels)
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise DataError(f"{path}: empty file")
    if path.suffix.lower() == ".png" and not _png_complete(data):
        raise DataError(f"{path}: truncated or corrupt PNG (no IEND chunk)")
    return header, data


def _decode_frame(path: Path, header: Header | None, data: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """The RGB frame (H, W, 3) uint8 of the file's bytes, EXIF orientation applied, and ``read_image_meta``'s
    record; DataError for what is not an 8-bit colour image."""
    if header is not None and _png_rgb8(data):  # the camera's frames: decoded straight to RGB, no copy to reorder
        return _decode_png_rgb8(path, data), {}
    img = _decode(path, data, cv2.IMREAD_UNCHANGED)
    if img.dtype != np.uint8:
        raise DataError(f"{path}: expected 8-bit image, got {img.dtype}")
    if img.ndim == 2:
        raise DataError(f"{path}: expected a colour (RGB) image, got a single-channel image")
    if img.shape[2] == 4:
        img = img[:, :, :3]
    elif img.shape[2] != 3:
        raise DataError(f"{path}: expected 3 colour channels, got {img.shape[2]}")
    orientation = header.orientation if header is not None else 1
    rgb = orient(img[:, :, ::-1], orientation)
    return np.ascontiguousarray(rgb), ({"exif_orientation": orientation} if orientation != 1 else {})


def image_size(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[int, int]:
    """(width, height) of an image as ``read_image`` returns it (orientation applied), from its header when it
    has a readable one (PNG, JPEG), else by decoding it; DataError like ``read_image``."""
    header = _checked_header(Path(path), max_pixels)
    if header is not None:
        return header.oriented_size
    img = read_image(path, max_pixels=max_pixels)
    return img.shape[1], img.shape[0]


def orient(img: np.ndarray, orientation: int) -> np.ndarray:
    """The stored pixels ``img`` (H, W, ...) turned upright by EXIF orientation 1..8 (as Pillow's exif_transpose)."""
    if orientation in (2, 4, 5, 7):  # mirrored: flip the columns first
        img = img[:, ::-1]
    turns = {3: 2, 4: 2, 5: 1, 6: 3, 7: 3, 8: 1}.get(orientation, 0)  # counter-clockwise quarter turns
    return np.rot90(img, turns) if turns else img


def _checked_header(path: Path, max_pixels: int) -> Header | None:
    """The file's header (None when its format has none we read); DataError when missing or above the limit."""
    max_pixels = check_max_pixels(max_pixels)
    if not path.exists():
        raise DataError(f"{path}: no such file")
    if not path.is_file():
        raise DataError(f"{path}: not a file")
    try:
        with open(path, "rb") as f:
            head = f.read(HEADER_BYTES)
            header = read_header(head)
            if header is None and head[:2] == b"\xff\xd8" and len(head) == HEADER_BYTES:  # metadata past 64 KiB
                head += f.read(MAX_HEADER_BYTES - HEADER_BYTES)
                header = read_header(head)
    except OSError as exc:
        raise DataError(f"{path}: unreadable: {exc.strerror or exc}") from None
    if header is not None:
        size = (header.width, header.height)
    else:
        try:
            size = pil_size(path)
        except OverflowError:
            raise DataError(f"{path}: image too large (Pillow refuses it as a decompression bomb; the limit is "
                            f"{max_pixels} pixels)") from None
    if size is not None and size[0] * size[1] > max_pixels:
        raise DataError(f"{path}: image of {size[0]}x{size[1]} pixels exceeds the limit of {max_pixels} pixels "
                        f"(max_pixels; 8K is 7680x4320); refused before decoding")
    if size is not None and min(size) < 1:
        raise DataError(f"{path}: image header claims a {size[0]}x{size[1]} frame")
    return header


def _decode(path: Path, data: np.ndarray, flags: int) -> np.ndarray:
    """``cv2.imdecode``; DataError naming the file when it cannot decode it."""
    try:
        img = cv2.imdecode(data, flags)
    except cv2.error as exc:  # e.g. OpenCV's own size limit on a format without a readable header
        raise DataError(f"{path}: not a readable image ({_first_line(str(exc))})") from None
    if img is None:
        raise DataError(f"{path}: not a readable image")
    return img


@functools.cache
def _spng() -> object | None:
    """libspng's decoder (``imagecodecs.spng_decode``, the optional ``fast`` extra) when installed, else None."""
    try:
        import imagecodecs  # optional heavy dependency: the ``fast`` extra
    except ImportError:
        return None
    return imagecodecs.spng_decode if imagecodecs.SPNG.available else None


def _decode_png_rgb8(path: Path, data: np.ndarray) -> np.ndarray:
    """An 8-bit RGB PNG's pixels (H, W, 3): by libspng where installed (about 30% faster than OpenCV's libpng on a
    3840x2160 frame here; the same pixels, PNG being lossless), else by OpenCV; DataError naming the file."""
    spng = _spng()
    if spng is not None:
        try:
            img = spng(data)  # type: ignore[operator]
        except Exception:  # noqa: BLE001 - a PNG libspng refuses is left to OpenCV, which names the problem
            img = None
        if img is not None and img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3:
            return img
    return _decode(path, data, cv2.IMREAD_COLOR_RGB | cv2.IMREAD_IGNORE_ORIENTATION)


def _png_rgb8(data: np.ndarray) -> bool:
    """Whether ``data`` is a PNG of 8-bit truecolour pixels without alpha (IHDR bit depth 8, colour type 2): the
    pixels ``IMREAD_UNCHANGED`` gives, channels reversed, are exactly those ``IMREAD_COLOR_RGB`` gives (a PNG
    carries no EXIF orientation here: :func:`el.base.imageheader.read_header` reads none)."""
    return (data.size > 26 and bytes(data[:8]) == PNG_SIGNATURE and bytes(data[12:16]) == b"IHDR"
            and int(data[24]) == 8 and int(data[25]) == 2)


def _first_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else "decoder error"


def _png_complete(data: np.ndarray) -> bool:
    """A PNG whose last chunk is IEND: catches files cut short, which decoders may half-read."""
    return data.size >= 20 and bytes(data[-12:-4]) == b"\x00\x00\x00\x00IEND"
