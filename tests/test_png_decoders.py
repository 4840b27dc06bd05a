"""The camera's 8-bit RGB PNG frames decode to the same pixels by libspng (the ``fast`` extra) as by OpenCV, and
without libspng the OpenCV path is taken: the decoder is a speed choice, never a decision change."""

import numpy as np
import pytest
from PIL import Image

from el.base import imageio


def _frames(tmp_path):
    rng = np.random.default_rng(0)
    out = []
    for name, interlace in (("plain", False), ("interlaced", True)):
        rgb = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
        rgb[:10] = 7  # some runs the PNG filters compress
        path = tmp_path / f"{name}.png"
        Image.fromarray(rgb).save(path, interlace=interlace)
        out.append((path, rgb))
    return out


def test_spng_and_opencv_give_the_same_pixels(tmp_path, monkeypatch):
    pytest.importorskip("imagecodecs")
    if imageio._spng() is None:
        pytest.skip("imagecodecs without libspng")
    for path, rgb in _frames(tmp_path):
        fast, _, sha_fast = imageio.read_image_hashed(path)
        monkeypatch.setattr(imageio, "_spng", lambda: None)
        slow, _, sha_slow = imageio.read_image_hashed(path)
        monkeypatch.undo()
        assert np.array_equal(fast, rgb) and np.array_equal(slow, rgb) and sha_fast == sha_slow


def test_without_spng_the_opencv_path_decodes(tmp_path, monkeypatch):
    monkeypatch.setattr(imageio, "_spng", lambda: None)
    for path, rgb in _frames(tmp_path):
        assert np.array_equal(imageio.read_image(path), rgb)


def test_a_png_libspng_refuses_is_named_by_the_fallback(tmp_path, monkeypatch):
    def refuse(data):
        raise RuntimeError("spng says no")

    monkeypatch.setattr(imageio, "_spng", lambda: refuse)
    path, rgb = _frames(tmp_path)[0]
    assert np.array_equal(imageio.read_image(path), rgb)  # OpenCV decodes what libspng refused
