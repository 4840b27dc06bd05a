"""Class names the certification basis knows, compared as a reader sees them (docs/architecture.md 2.1).

A label set names its own classes, and declares for each a hazard category (``el.classes.label_tables.CATEGORIES``). For
the well-known names of :data:`PINNED_CATEGORIES` (road, street, car, building, person, water, ...) the category is
not the set's to choose: the certification basis (``assurance.requirements.basis``) pins it, and a set declaring
another one deviates from the basis. Two spellings a reader cannot tell apart must not be two classes:

- :func:`class_key` is how names are compared: NFKC, case-folded, every run of separators (``_``, ``-``, any dash,
  any space) one space: ``Paved_Area``, ``paved-area`` and ``PAVED AREA`` are one name, ``paved area``;
- :func:`skeleton` is what a name looks like, after Unicode TS 39 with ICU's full confusables data
  (``el.classes.name_profile.skeleton``): the Cyrillic ``rоad`` and ``road`` share one.

:func:`check_class_names` refuses a set holding a class whose name is outside the restricted identifier profile
(``el.classes.name_profile``: Latin letters of TS 39's recommended set after NFKC, digits, ``-``, ``_``, spaces; so no
small capitals ``ʀᴏᴀᴅ``, no Cyrillic, Armenian or Cherokee letter, nothing invisible or blank-looking), a class
that looks like a well-known name without being it (its category would escape the pin), or two classes that look
alike (the reader of a report cannot tell which is which).
This module holds data and pure functions: ``el`` and ``assurance`` both read it.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Iterable, Mapping

from el.classes.name_profile import profile_problem
from el.classes.name_profile import skeleton as name_skeleton

_BY_CATEGORY: dict[str, tuple[str, ...]] = {
    "road": ("road", "street", "paved area", "highway", "motorway", "freeway", "asphalt", "carriageway",
             "roadway", "avenue", "parking lot", "driveway",
             # synonyms and other languages of the review (issue 57); no list is complete: page 1 shows the pixels
             "lane", "tarmac", "car park", "parking", "parking area", "parking space", "sidewalk", "pavement",
             "crosswalk", "junction", "roundabout", "straße", "strasse", "rue", "route", "chaussée", "calle",
             "carretera", "strada", "weg"),
    "vehicle": ("vehicle", "car", "truck", "lorry", "bus", "van", "motorcycle", "motorbike", "bicycle", "bike",
                "scooter", "tractor", "train", "tram", "static car", "moving car", "parked car",
                "automobile", "auto", "suv", "pickup", "trailer", "boat", "voiture", "véhicule", "fahrzeug", "coche",
                "vehículo", "veicolo", "macchina"),
    "building": ("building", "roof", "rooftop", "house", "wall", "window", "door", "garage", "shed", "tower",
                 "construction", "structure", "bâtiment", "gebäude", "dach", "toit", "maison", "edificio", "casa",
                 "haus", "häuser", "wand", "mauer", "immeuble", "mur", "tetto", "techo"),
    "person": ("person", "human", "pedestrian", "people", "rider", "cyclist", "crowd", "mensch", "menschen",
               "personne", "piéton", "persona", "peatón"),
    "animal": ("animal", "dog", "cat", "horse", "cow", "sheep", "livestock"),
    "water": ("water", "pool", "swimming pool", "river", "lake", "sea", "pond", "ocean", "canal", "stream",
              "fountain", "eau", "wasser", "agua", "acqua", "rivière", "fluss", "río", "fiume"),
    "obstacle": ("fence", "fence pole", "pole", "obstacle", "power line"),
}


def _plural(name: str) -> str:
    return name + ("es" if name.endswith(("s", "sh", "ch", "x")) else "s")


_SEPARATORS = re.compile(r"[\s_\-\u2010-\u2015\u2212\u2043\ufe58\ufe63\uff0d]+")

def class_key(name: str) -> str:
    """How class names are compared: NFKC, case-folded, separators one space, trimmed (``Paved_Area`` ->
    ``paved area``)."""
    return _SEPARATORS.sub(" ", unicodedata.normalize("NFKC", str(name)).casefold()).strip()


PINNED_CATEGORIES: Mapping[str, str] = {
    class_key(form): category for category, names in _BY_CATEGORY.items() for name in names
    for form in (name, _plural(name))
}
"""Well-known class name (as :func:`class_key` writes it; plurals too) -> the hazard category the basis pins."""


def skeleton(name: str) -> str:
    """What a name looks like (Unicode TS 39 skeleton, ICU's data: ``el.classes.name_profile.skeleton``): two names
    with one
    skeleton are confusable."""
    return name_skeleton(name)


def pinned_category(name: str) -> str | None:
    """The hazard category the basis pins for a well-known class name (any spelling :func:`class_key` merges);
    None for a name it does not know."""
    return PINNED_CATEGORIES.get(class_key(name))


_KNOWN_SKELETONS: dict[str, str] = {}
for _known in PINNED_CATEGORIES:
    _KNOWN_SKELETONS.setdefault(skeleton(_known), _known)


def shown(name: str) -> str:
    """A name as a message shows it: its repr, and its escapes when it holds anything but printable ASCII (a
    Cyrillic ``о`` reads as ``o``)."""
    text = repr(name)
    return text if text.isascii() else f"{text} (written {ascii(name)})"


def check_class_names(set_name: str, names: Iterable[str]) -> None:
    """ValueError naming the label set and the class when a class name is outside the restricted identifier profile
    (``el.classes.name_profile.profile_problem``), looks like a well-known name without being it, or two classes look
    alike
    (one :func:`class_key` or one :func:`skeleton`)."""
    seen: dict[str, str] = {}
    for name in names:
        key, sk = class_key(name), skeleton(name)
        known = _KNOWN_SKELETONS.get(sk)
        why = profile_problem(name)
        if known is not None and key not in PINNED_CATEGORIES:
            raise ValueError(f"label set {set_name!r}: class {shown(name)} looks like the well-known class name "
                             f"{known!r} (Unicode TS 39 skeleton {sk!r}) but is not it: refused (its hazard category "
                             f"would escape the basis's pin, {PINNED_CATEGORIES[known]}); call it {known!r} or give "
                             "it a name of its own" + ("" if why is None else f" (and {why})"))
        if why is not None:
            raise ValueError(f"label set {set_name!r}: class {shown(name)} is outside the class-name profile (Unicode "
                             "TS 39 restricted: Latin letters, digits, '-', '_' and spaces after NFKC; "
                             f"el.classes.name_profile): {why}; refused, rename it")
        for other in (seen.get(f"key:{key}"), seen.get(f"skeleton:{sk}")):
            if other is not None and other != name:
                raise ValueError(f"label set {set_name!r}: classes {shown(other)} and {shown(name)} look alike (one "
                                 f"name once normalised and case-folded, or one Unicode TS 39 skeleton {sk!r}): "
                                 "refused; give each class a distinct name")
        seen.setdefault(f"key:{key}", name)
        seen.setdefault(f"skeleton:{sk}", name)


__all__ = ["PINNED_CATEGORIES", "check_class_names", "class_key", "pinned_category", "shown", "skeleton"]
