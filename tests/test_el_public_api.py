"""``el``'s public face (issue 58): ``__all__`` names the flight API, each name loads on first use from the module
the table in docs/flight-api.md names, and the flat paths of earlier releases import as the very same modules."""

import importlib
import subprocess
import sys

import pytest

import el


def test_every_public_name_resolves_to_its_module() -> None:
    for name in el.__all__:
        value = getattr(el, name)
        assert getattr(importlib.import_module(el.API[name]), name) is value


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        el.nothing_here  # noqa: B018


@pytest.mark.parametrize("old", sorted(el.MOVED))
def test_an_old_flat_path_is_the_same_module(old: str) -> None:
    module = importlib.import_module(old)
    assert module is importlib.import_module(el.MOVED[old])
    assert module.__spec__.name == el.MOVED[old]  # the module's own spec, not the alias's


def test_the_old_path_of_the_docs_example_still_works() -> None:
    from el.pipeline import EmergencyLanding  # noqa: I001 (the path of earlier releases)

    assert EmergencyLanding is el.EmergencyLanding


def test_import_el_is_light() -> None:
    code = "import sys, el; heavy = [m for m in ('numpy', 'torch', 'cv2', 'onnxruntime') if m in sys.modules]; " \
           "print(','.join(heavy))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""


def test_each_layer_is_a_folder() -> None:
    from pathlib import Path

    root = Path(el.__file__).parent
    flat = sorted(p.stem for p in root.glob("*.py") if p.stem != "__init__")
    assert flat == [], f"modules outside a layer's folder: {flat}"
