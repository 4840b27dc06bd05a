"""Fault-injection cases of class names, categories and colours (issue 57; rows ``T70``..``T79``).

A label set's words are the applicant's: a class name outside the restricted identifier profile (small capitals,
Armenian or Cherokee letters, a Braille blank, a Hangul filler: ``el.classes.name_profile``) is refused when the set is
read
(exit 2, one line naming the set, the class and the character); a safe class of the category ``unknown`` (declared or
implied) and a safe class in a colour a well-known label set gives a forbidden class are deviations named on the
first page, which still states the gate's own verdict and shows each safe class's pixels on the run's frames; so is
a synonym or another language's word for road declared safe (``Straße``: its category is pinned); two classes
sharing a colour are refused. UAVid's own clutter is a deviation the basis itself accepts, in the open.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from assurance.fault_injection.basis_cases import _uavid_doc, _write_labels
from assurance.fault_injection.case import Case
from assurance.fault_injection.report_cases import _states_alone, read_report
from assurance.fault_injection.trust import _evidence, _system


def _labels_evidence(ws: Path, name: str, doc: dict) -> list[str]:
    """``uav-el evidence`` on the workspace's run, judged with a system file naming the label set ``doc``."""
    labels = _write_labels(ws / f"labels-{name}.yaml", doc)
    return _evidence(ws, name, "--system", _system(ws, f"sys-{name}", f'[labels]\nfile = "{labels.name}"\n'))


def _road_renamed(ws: Path, name: str, case: str, category: str = "bare_ground") -> list[str]:
    """UAVid's road renamed ``name`` and declared safe (``category``, score 0), in road's colour."""
    return _labels_evidence(ws, case, _uavid_doc(name=name, forbidden=False, hazard_score=0.0, category=category))


def _meadow_in_roads_colour(ws: Path) -> list[str]:
    """A safe 'meadow' (vegetation) holding road's colour, road kept forbidden in a colour no pixel has: flown, the
    roads of the data are meadow."""
    doc = _uavid_doc(rgb=[1, 2, 3])
    doc["classes"].append({"id": len(doc["classes"]), "name": "meadow", "rgb": [128, 64, 128], "forbidden": False,
                           "hazard_score": 0.0, "category": "vegetation"})
    return _labels_evidence(ws, "meadow", doc)


def _unknown_declared(ws: Path) -> list[str]:
    """UAVid's classes under another set name: its clutter (safe, declared ``unknown``) is no longer the set the
    basis accepts it for."""
    doc = _uavid_doc()
    doc["name"] = "city-survey"
    return _labels_evidence(ws, "unknown", doc)


def _shared_colour(ws: Path) -> list[str]:
    """Road's colour given to low vegetation as well: two classes, one colour."""
    doc = _uavid_doc()
    next(c for c in doc["classes"] if c["name"] == "low_vegetation")["rgb"] = [128, 64, 128]
    return _labels_evidence(ws, "shared-colour", doc)


def _first_page(name: str, *, deviation: str, strip: str, accepted: bool = False) -> Callable[[Path], str | None]:
    """A check: ``rep-NAME``'s first page states the gate's verdict and no other, lists ``deviation`` (accepted by
    the basis with ``accepted``, else not accepted) and shows a strip of the safe class ``strip``."""

    def check(ws: Path) -> str | None:
        found = read_report(ws / f"rep-{name}")
        if isinstance(found, str):
            return found
        html, verdict = found
        cover = html.split('<header class="toc">', 1)[0]
        if not _states_alone(cover, verdict):
            return f"the first page does not state the gate's verdict {verdict} alone"
        line = next((li for li in cover.split("<li>") if f"<strong>{deviation}</strong>" in li), None)
        if line is None:
            return f"the first page does not list the deviation {deviation}"
        state = "accepted by the certification basis" if accepted else "not accepted"
        if state not in line:
            return f"the first page lists {deviation} but not as {state}"
        if "What each safe class covers" not in cover or f"<strong>{strip}</strong> (safe" not in cover:
            return f"the first page shows no strip of the safe class {strip}"
        return None

    return check


NAME_CASES: tuple[Case, ...] = (
    Case("T70-small-capitals-road", "UAVid's road renamed '\u0280\u1d0f\u1d00\u1d05' (small capitals), declared safe",
         lambda ws: _road_renamed(ws, "\u0280\u1d0f\u1d00\u1d05", "small-caps"), 2,
         "LATIN LETTER SMALL CAPITAL R is not in Unicode TS 39's recommended identifier set"),
    Case("T71-armenian-road", "UAVid's road renamed 'r\u0585ad' (an Armenian oh), declared safe",
         lambda ws: _road_renamed(ws, "r\u0585ad", "armenian"), 2, "looks like the well-known class name 'road'"),
    Case("T72-cherokee-road", "UAVid's road renamed '\u13a1OAD' (a Cherokee E), declared safe",
         lambda ws: _road_renamed(ws, "\u13a1OAD", "cherokee"), 2, "looks like the well-known class name 'road'"),
    Case("T73-braille-blank-road", "UAVid's road renamed 'road' + U+2800 BRAILLE PATTERN BLANK, declared safe",
         lambda ws: _road_renamed(ws, "road\u2800", "braille"), 2, "BRAILLE PATTERN BLANK is invisible or blank"),
    Case("T74-hangul-filler-road", "UAVid's road renamed U+3164 HANGUL FILLER + 'road', declared safe",
         lambda ws: _road_renamed(ws, "\u3164road", "hangul"), 2, "HANGUL JUNGSEONG FILLER is invisible or blank"),
    Case("T75-meadow-in-roads-colour", "a safe 'meadow' holding road's colour, road kept in an unused one",
         _meadow_in_roads_colour, 1, "colour:meadow = safe, painted RGB(128, 64, 128)", pick="colour:meadow",
         check=_first_page("meadow", deviation="colour:meadow", strip="meadow")),
    Case("T76-safe-class-declared-unknown", "UAVid's classes as another set: clutter safe with category unknown",
         _unknown_declared, 1, "class:clutter = declared safe with category unknown", pick="class:clutter",
         check=_first_page("unknown", deviation="class:clutter", strip="clutter")),
    Case("T77-shipped-clutter-in-the-open", "the shipped UAVid set: its clutter is safe with category unknown",
         lambda ws: _labels_evidence(ws, "shipped-clutter", _uavid_doc()), 1, "",
         check=_first_page("shipped-clutter", deviation="class:clutter", strip="clutter", accepted=True)),
    Case("T78-two-classes-one-colour", "low vegetation given road's colour as well", _shared_colour, 2,
         "classes 'road' and 'low_vegetation' share the colour RGB(128, 64, 128)"),
    Case("T79-synonym-declared-safe", "UAVid's road renamed 'Stra\u00dfe', declared safe as vegetation",
         lambda ws: _road_renamed(ws, "Stra\u00dfe", "synonym", category="vegetation"), 1,
         "category road, pinned for the name 'Stra\u00dfe'", pick="class:Stra\u00dfe",
         check=_first_page("synonym", deviation="class:Stra\u00dfe", strip="Stra\u00dfe")),
)
"""Class names, categories and colours (module docstring): assembled with the applicant's cases in
``assurance.fault_injection.applicant``."""
