"""UAVid-layout reader/writer: pairing, sizes, and clear errors naming the file."""

import numpy as np
import pytest

from assurance.dataio.uavid import DataError, iter_samples, read_image, read_labels, write_image, write_sample
from el.classes.labels import UAVID


def _rgb(h=12, w=16, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


def test_write_and_read_back(tmp_path):
    ids = np.random.default_rng(1).integers(0, 8, (12, 16)).astype(np.uint8)
    img = _rgb()
    write_sample(tmp_path, "seq01", "000000", img, ids, labels=UAVID)
    write_sample(tmp_path, "seq01", "000001", img, ids, labels=UAVID)
    samples = list(iter_samples(tmp_path, check_sizes=True))
    assert [s.key for s in samples] == ["seq01/000000", "seq01/000001"]
    np.testing.assert_array_equal(read_image(samples[0].image_path), img)
    np.testing.assert_array_equal(read_labels(samples[0].label_path, labels=UAVID), ids)


def test_unpaired_image_is_named(tmp_path):
    ids = np.zeros((12, 16), np.uint8)
    write_sample(tmp_path, "seq01", "000000", _rgb(), ids, labels=UAVID)
    write_image(tmp_path / "seq01" / "Images" / "000007.png", _rgb())
    with pytest.raises(DataError, match="000007.*has no label"):
        list(iter_samples(tmp_path))


def test_unpaired_label_is_named(tmp_path):
    ids = np.zeros((12, 16), np.uint8)
    write_sample(tmp_path, "seq01", "000000", _rgb(), ids, labels=UAVID)
    (tmp_path / "seq01" / "Images" / "000000.png").unlink()
    with pytest.raises(DataError, match="000000.png: label has no image"):
        list(iter_samples(tmp_path))


def test_size_mismatch_is_named(tmp_path):
    write_sample(tmp_path, "seq01", "000000", _rgb(), np.zeros((12, 16), np.uint8), labels=UAVID)
    write_image(tmp_path / "seq01" / "Labels" / "000000.png", np.zeros((10, 16, 3), np.uint8))
    with pytest.raises(DataError, match="differs from image"):
        list(iter_samples(tmp_path, check_sizes=True))


def test_missing_root_and_empty_root(tmp_path):
    with pytest.raises(DataError, match="not found"):
        list(iter_samples(tmp_path / "nope"))
    with pytest.raises(DataError, match="no seqNN"):
        list(iter_samples(tmp_path))


def test_bad_image_files(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_image(tmp_path / "missing.png")
    text = tmp_path / "notes.png"
    text.write_text("hello, not an image")
    with pytest.raises(DataError, match="notes.png"):
        read_image(text)
    good = tmp_path / "good.png"
    write_image(good, _rgb(64, 64))
    cut = tmp_path / "cut.png"
    cut.write_bytes(good.read_bytes()[:-40])
    with pytest.raises(DataError, match="cut.png: truncated"):
        read_image(cut)
