"""What an image file says about itself before it is decoded: its size (PNG IHDR, JPEG SOF) and EXIF orientation.

Read from the first bytes only, so a file claiming a frame too large to hold is refused before a decoder
allocates it (``el.base.imageio.read_image``). Other formats are sized by Pillow's lazy open when it is
installed, else left to the decoder's own limit.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_STANDALONE = {0x01, *range(0xD0, 0xD8)}
ORIENTATION_TAG = 0x0112
ORIENTATIONS = range(1, 9)  # EXIF: 1 as stored, 2..8 flips and quarter turns


@dataclass(frozen=True)
class Header:
    """Stored ``width`` x ``height`` in pixels (before orientation), the format, and the EXIF orientation
    (1 when the file has none)."""

    width: int
    height: int
    format: str
    orientation: int = 1

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def oriented_size(self) -> tuple[int, int]:
        """(width, height) once the EXIF orientation is applied (5..8 swap the sides)."""
        return (self.height, self.width) if self.orientation >= 5 else (self.width, self.height)


def read_header(data: bytes) -> Header | None:
    """The header of a PNG or JPEG held in ``data`` (its first bytes suffice); None for another format or
    a header too damaged to read (the decoder then says what is wrong)."""
    if data[:8] == PNG_SIGNATURE:
        if len(data) >= 24 and data[12:16] == b"IHDR":
            w, h = struct.unpack(">II", data[16:24])
            return Header(w, h, "png")
        return None
    if data[:2] == b"\xff\xd8":
        return _jpeg_header(data)
    return None


def _jpeg_header(data: bytes) -> Header | None:
    """Walk the JPEG markers up to the first start-of-frame; EXIF orientation from an APP1 on the way."""
    i, orientation = 2, 1
    n = len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _STANDALONE:
            i += 2
            continue
        if marker == 0xDA:  # start of scan before any frame header
            return None
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if length < 2:
            return None
        segment = data[i + 4:i + 2 + length]
        if marker in _SOF:
            if len(segment) < 5:
                return None
            h, w = struct.unpack(">HH", segment[1:5])
            return Header(w, h, "jpeg", orientation)
        if marker == 0xE1 and segment[:6] == b"Exif\x00\x00":
            orientation = exif_orientation(segment[6:])
        i += 2 + length
    return None


def exif_orientation(tiff: bytes) -> int:
    """The Orientation tag (0x0112) of IFD0 of an EXIF block (TIFF layout); 1 when absent or malformed."""
    if len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return 1
    end = "<" if tiff[:2] == b"II" else ">"
    try:
        if struct.unpack(end + "H", tiff[2:4])[0] != 42:
            return 1
        ifd = struct.unpack(end + "I", tiff[4:8])[0]
        count = struct.unpack(end + "H", tiff[ifd:ifd + 2])[0]
        for k in range(count):
            entry = tiff[ifd + 2 + 12 * k: ifd + 14 + 12 * k]
            tag, typ = struct.unpack(end + "HH", entry[:4])
            if tag == ORIENTATION_TAG and typ == 3:  # SHORT
                value = struct.unpack(end + "H", entry[8:10])[0]
                return value if value in ORIENTATIONS else 1
    except struct.error:
        return 1
    return 1


def pil_size(path: object) -> tuple[int, int] | None:
    """(width, height) from Pillow's lazy open (no pixel decoded); None without Pillow or when it cannot tell.

    OverflowError when Pillow itself refuses the size as a decompression bomb (far above any frame limit)."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow ships with matplotlib
        return None
    try:
        with Image.open(path) as im:  # type: ignore[arg-type]
            return int(im.size[0]), int(im.size[1])
    except Image.DecompressionBombError as exc:
        raise OverflowError(str(exc)) from None
    except Exception:  # not an image Pillow knows: the decoder decides
        return None
