"""The safety argument (GSN), generated from the requirement registry, the hazard log and the evidence, never typed:
a top goal, strategies over the hazards, over the requirements and over the ML component per AMLAS stage, solutions
that are the evidence items with their hashes and verdicts. Exported in gsn2x's YAML schema and checked by
``check_structure`` (one top goal, unique ids, references defined, no cycles, every element reachable)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from assurance import requirements as rq
from el.base.safeyaml import safe_load

KINDS = {"G": "Goal", "S": "Strategy", "Sn": "Solution", "C": "Context", "A": "Assumption", "J": "Justification"}
"""gsn2x's element prefixes (the id's part before the first '-')."""
SUPPORTING = ("Goal", "Strategy", "Solution")
CONTEXTUAL = ("Context", "Assumption", "Justification")


@dataclass
class Node:
    """One GSN element: its id (gsn2x prefix + identifier), text, links and verdict class."""

    id: str
    text: str
    supported_by: list[str] = field(default_factory=list)
    in_context_of: list[str] = field(default_factory=list)
    undeveloped: bool = False
    cls: str = ""  # verified | failed | waived | not-verified | "" (no verdict)

    @property
    def kind(self) -> str:
        """The GSN element type, from the id's prefix."""
        return KINDS.get(self.id.split("-", 1)[0], "?")


@dataclass(frozen=True)
class ArgumentInputs:
    """What the argument is built from: registry, hazard log, requirement states and evidence."""

    registry: rq.Registry
    hazards: Any  # assurance.evidence.hazards.HazardLog
    results: Mapping[str, rq.RequirementResult]
    waivers: Mapping[str, Mapping[str, Any]]  # the waived requirements' waivers
    checks: Mapping[str, rq.Evidence]
    hashes: Mapping[str, str]  # 'requirements' / 'results' / 'system' / 'run' -> SHA-256
    amlas: Sequence[Mapping[str, Any]] = ()  # the AMLAS index (assurance.evidence.amlas)
    system: str = "the system assessed"
    domain_source: str = "the system assessed"  # whose values fill the registry's wording of the domain


def _short(sha: str | None) -> str:
    return f"SHA-256 {sha[:12]}" if sha else "not hashed"


def _requirement_nodes(a: ArgumentInputs, req: rq.Requirement) -> list[Node]:
    """A requirement's goal with its solutions (or undeveloped), and a waiver's justification."""
    res = a.results.get(req.id)
    state = res.state if res else rq.NOT_VERIFIED
    gid = f"G-{req.id}"
    if state == rq.NOT_VERIFIED:
        why = res.reason if res else "no result"
        return [Node(gid, f"{req.id} holds: {req.title} (NOT VERIFIED: {why})", undeveloped=True, cls="not-verified")]
    waived = req.id in a.waivers
    cls = "waived" if waived else ("verified" if state == rq.VERIFIED else "failed")
    verdict = {"verified": "verified", "failed": "FAILED", "waived": "FAILED, waived"}[cls]
    goal = Node(gid, f"{req.id} holds: {req.title} ({verdict})", cls=cls)
    out = [goal]
    tests = res.tests if res else []
    outcomes: dict[str, int] = {}
    for t in tests:
        outcomes[t.outcome] = outcomes.get(t.outcome, 0) + 1
    told = ", ".join(f"{n} {o}" for o, n in sorted(outcomes.items())) or "none"
    sn = Node(f"Sn-{req.id}-T", f"Requirement tests of {req.id}: {told} (requirements.json, "
                                f"{_short(a.hashes.get('requirements'))})", cls="verified" if state == rq.VERIFIED
              else "failed")
    goal.supported_by.append(sn.id)
    out.append(sn)
    ev = a.checks.get(req.id)
    if ev is not None:
        ok = ev.status == rq.PASS
        out.append(Node(f"Sn-{req.id}-C", f"Campaign check '{ev.name}': {ev.status} (results.csv, "
                                          f"{_short(a.hashes.get('results'))})",
                        cls="verified" if ok else ("failed" if ev.status == rq.FAIL else "not-verified")))
        goal.supported_by.append(out[-1].id)
    if waived:
        w = a.waivers[req.id]
        out.append(Node(f"J-{req.id}", f"Waiver owned by {w.get('owner', '?')}, expires {w.get('expires', '?')}: "
                                       f"{w.get('reason', '')}", cls="waived"))  # owner first: the drawing clips
        goal.in_context_of.append(out[-1].id)
    return out


AMLAS_STAGES = ((1, "ML safety assurance scoping"), (2, "ML safety requirements assurance"),
                (3, "Data management assurance"), (4, "Model learning assurance"),
                (5, "Model verification assurance"), (6, "Model deployment assurance"))


def monitor_words(spec: Any) -> str:
    """The deployed runtime monitor by its kind (``learned:walk=...`` -> the learned one, ``verifier:fuse=learned``
    -> the verifier fused with it, ``lhd+ch:tau=0.25`` -> ``lhd+ch``), as the argument names it beside the
    network."""
    kind, _, params = str(spec or "").partition(":")
    kind = kind.strip()
    if kind == "learned":
        return "learned runtime monitor"
    if kind == "verifier":
        fused = "fuse=learned" in params.split(",")
        return "candidate verifier fused with the learned runtime monitor" if fused else "candidate verifier"
    return f"deployed runtime monitor {kind}" if kind and kind != "none" else "no runtime monitor deployed"


def _ml_nodes(a: ArgumentInputs) -> list[Node]:
    """The AMLAS strategy: one goal per stage, supported by that stage's artefacts (undeveloped without any)."""
    strat = Node("S-ML", f"Argument over the ML component (segmentation network and "
                         f"{monitor_words(a.registry.parameters.get('deployed_monitor'))}) per AMLAS stage")
    out = [strat]
    for stage, name in AMLAS_STAGES:
        items = [x for x in a.amlas if x.get("stage") == stage]
        goal = Node(f"G-AMLAS{stage}", f"AMLAS stage {stage}: {name} is sufficient", undeveloped=not items,
                    cls="" if items else "not-verified")
        strat.supported_by.append(goal.id)
        out.append(goal)
        for k, x in enumerate(items, 1):
            sid = f"Sn-AMLAS{stage}-{x['letter']}{k}"
            out.append(Node(sid, f"[{x['letter']}] {x['artefact']}: {x['item']} ({_short(x.get('sha256'))})",
                            cls=x.get("cls", "")))
            goal.supported_by.append(sid)
    return out


def _worst(a: ArgumentInputs, rids: Sequence[str]) -> str:
    """A hazard's verdict: the worst of its mitigating requirements' (failed, waived, not verified, verified)."""
    states = [a.results[r].state if r in a.results else rq.NOT_VERIFIED for r in rids]
    if any(s == rq.FAILED and r not in a.waivers for s, r in zip(states, rids, strict=True)):
        return "failed"
    if any(s == rq.FAILED for s in states):
        return "waived"
    return "not-verified" if rq.NOT_VERIFIED in states else "verified"


def build_argument(a: ArgumentInputs) -> dict[str, Node]:
    """The argument's elements by id, in drawing order: top goal and context, then the three strategies."""
    reg, log = a.registry, a.hazards
    top = Node("G-TOP", f"The EL function is acceptably safe within its declared operating domain, for {a.system}",
               supported_by=["S-HAZ", "S-REQ", "S-ML"], in_context_of=["C-ODD", "C-SYS", "C-HAZ"])
    odd = "; ".join(f"{k.replace('_', ' ')}: {v}" for k, v in list(reg.operating_domain.items())[:3])
    nodes = [top,
             Node("C-ODD", f"Declared operating domain ({a.domain_source}, in the wording of {reg.path.name}): "
                           f"{odd}"),
             Node("C-SYS", f"System assessed: {a.system}; campaign run {_short(a.hashes.get('run'))}; system file "
                           f"{_short(a.hashes.get('system'))}"),
             Node("C-HAZ", f"Hazard log {log.path.name} ({_short(log.sha256)}): {len(log.hazards)} hazards")]
    shaz = Node("S-HAZ", "Argument over each hazard of the hazard log: every hazard is mitigated by requirements "
                         "that hold")
    nodes.append(shaz)
    for h in log.hazards:
        g = Node(f"G-{h.id}", f"{h.id} ({h.severity}) is mitigated: {h.hazard}",
                 supported_by=[f"G-{r}" for r in h.mitigations], cls=_worst(a, h.mitigations))
        shaz.supported_by.append(g.id)
        nodes.append(g)
    sreq = Node("S-REQ", f"Argument over every requirement of the registry ({reg.path.name}, "
                         f"{_short(reg.sha256)}): each is verified by its evidence", in_context_of=["J-GATE"])
    nodes += [sreq, Node("J-GATE", "A requirement holds when every claiming test passed on this run and the "
                                   "report's own check of the run agrees; failed and waived ones are shown as such")]
    for req in reg:
        req_nodes = _requirement_nodes(a, req)
        sreq.supported_by.append(req_nodes[0].id)
        nodes += req_nodes
    nodes += _ml_nodes(a)
    return {n.id: n for n in nodes}


def check_structure(nodes: Mapping[str, Node] | Sequence[Node]) -> list[str]:
    """What breaks the argument's structure (empty when sound): ids unique and well-typed, exactly one top goal,
    every reference defined and of the right type, no cycle, every element reachable from the top goal, every goal
    or strategy developed or marked undeveloped."""
    items = list(nodes.values()) if isinstance(nodes, Mapping) else list(nodes)
    problems: list[str] = []
    seen: dict[str, Node] = {}
    for n in items:
        if n.id in seen:
            problems.append(f"{n.id}: id used twice")
        if n.kind == "?":
            problems.append(f"{n.id}: unknown element type (prefix not one of {', '.join(KINDS)})")
        seen[n.id] = n
    for n in items:
        for ref in n.supported_by:
            if ref not in seen:
                problems.append(f"{ref}: supports {n.id} but is not defined in the argument")
            elif seen[ref].kind not in SUPPORTING:
                problems.append(f"{n.id}: supportedBy {ref}, a {seen[ref].kind}")
        for ref in n.in_context_of:
            if ref not in seen:
                problems.append(f"{ref}: context of {n.id} but is not defined in the argument")
            elif seen[ref].kind not in CONTEXTUAL:
                problems.append(f"{n.id}: inContextOf {ref}, a {seen[ref].kind}")
        if n.kind in ("Goal", "Strategy") and not n.supported_by and not n.undeveloped:
            problems.append(f"{n.id}: {n.kind.lower()} neither supported nor marked undeveloped")
        if n.undeveloped and n.supported_by:
            problems.append(f"{n.id}: marked undeveloped but supported")
    referenced = {r for n in items for r in (*n.supported_by, *n.in_context_of)}
    tops = [n.id for n in items if n.id not in referenced and n.kind == "Goal"]
    if len(tops) != 1:
        problems.append(f"{len(tops)} top goals ({', '.join(tops) or 'none'}); an argument has exactly one")
    problems += _cycles(seen)
    if len(tops) == 1:
        reach = _reachable(seen, tops[0])
        problems += [f"{n.id}: not reachable from the top goal {tops[0]}" for n in items if n.id not in reach]
    return problems


def _reachable(nodes: Mapping[str, Node], start: str) -> set[str]:
    out, todo = set(), [start]
    while todo:
        nid = todo.pop()
        if nid in out or nid not in nodes:
            continue
        out.add(nid)
        todo += nodes[nid].supported_by + nodes[nid].in_context_of
    return out


def _cycles(nodes: Mapping[str, Node]) -> list[str]:
    """One line per supportedBy cycle found (depth-first, colours)."""
    state: dict[str, int] = {}
    found: list[str] = []

    def visit(nid: str, path: list[str]) -> None:
        state[nid] = 1
        for ref in nodes[nid].supported_by:
            if ref not in nodes:
                continue
            if state.get(ref) == 1:
                found.append("cycle: " + " -> ".join([*path[path.index(ref):], ref]))
            elif ref not in state:
                visit(ref, [*path, ref])
        state[nid] = 2

    for nid in nodes:
        if nid not in state:
            visit(nid, [nid])
    return found


def to_gsn2x(nodes: Mapping[str, Node]) -> dict[str, dict[str, Any]]:
    """The argument in gsn2x's YAML schema: element id -> text, supportedBy, inContextOf, undeveloped, classes."""
    doc: dict[str, dict[str, Any]] = {}
    for n in nodes.values():
        e: dict[str, Any] = {"text": n.text}
        if n.supported_by:
            e["supportedBy"] = list(n.supported_by)
        if n.in_context_of:
            e["inContextOf"] = list(n.in_context_of)
        if n.undeveloped:
            e["undeveloped"] = True
        if n.cls:
            e["classes"] = [n.cls]
        doc[n.id] = e
    return doc


def to_yaml(nodes: Mapping[str, Node]) -> str:
    """The gsn2x YAML text of the argument (``gsn2x argument.gsn.yaml`` draws it)."""
    import yaml

    head = "# GSN safety argument generated by uav-el evidence (gsn2x YAML schema); do not edit: regenerate it.\n"
    return head + yaml.safe_dump(to_gsn2x(nodes), sort_keys=False, allow_unicode=True, width=100)


def from_yaml(text: str) -> dict[str, Node]:
    """Read a gsn2x YAML argument back (ValueError for one that is not a mapping of elements with a text)."""
    doc = safe_load(text)
    if not isinstance(doc, dict):
        raise ValueError("a GSN argument is a mapping of element ids")
    out = {}
    for nid, e in doc.items():
        if not isinstance(e, dict) or not isinstance(e.get("text"), str):
            raise ValueError(f"{nid}: a GSN element needs a text")
        out[str(nid)] = Node(str(nid), e["text"], list(e.get("supportedBy") or []), list(e.get("inContextOf") or []),
                             bool(e.get("undeveloped", False)), (e.get("classes") or [""])[0])
    return out
