"""The CH monitor's classification hierarchy, loaded from ``hierarchy.yaml`` (data, not code).

A pixel is labelled with the closest common ancestor (LCA) of the classes whose score exceeds tau.
With 8 classes a pixel's "classes above tau" is an 8-bit mask, so the LCA of every possible mask is
precomputed once (256 entries) and labelling a patch is a table look-up (docs/architecture.md section 3.6).

Node ids: the leaves keep their class ids (0..7, el/labels.py); inner nodes follow (8, 9, ...).

A hierarchy belongs to a label set (``labels``, default :data:`el.labels.UAVID`): its classes are the
leaves. :func:`default_hierarchy` gives the set's own tree (the shipped file for UAVid).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from el import safeyaml
from el.labels import UAVID, LabelSet

HIERARCHY_FILE = "hierarchy.yaml"
MAX_HIERARCHY_CLASSES = 16  # a pixel's classes above tau are a 16-bit mask; the LCA table has 2**n entries


@dataclass(frozen=True, eq=False)
class ClassHierarchy:
    """A class tree over a label set's classes (UAVid by default), with its LCA table and the nodes a monitor rejects.

    Parameters
    ----------
    nodes : tuple of str
        Node names; ``nodes[i]`` is node id ``i``. The first ``num_classes`` are the classes, in
        class-id order.
    parents : tuple of int
        Parent node id of each node, ``-1`` for the root.
    labels : LabelSet, default UAVID
        The label set whose classes are the leaves (at most 16 classes).

    Attributes
    ----------
    root : int
        The root's node id (the label of a pixel with no class above tau).
    lca_table : ndarray of shape (2**num_classes,), int16
        ``lca_table[m]`` is the LCA of the classes whose bits are set in ``m`` (the root for ``m = 0``).
    rejected : ndarray of shape (len(nodes),), bool
        True for nodes with a forbidden class under them (the root, ``unsafe`` and the forbidden
        leaves with the shipped tree): a disc pixel with such a label makes CH reject.
    """

    nodes: tuple[str, ...]
    parents: tuple[int, ...]
    labels: LabelSet = field(default=UAVID, repr=False)
    root: int = field(init=False)
    lca_table: np.ndarray = field(init=False, repr=False)
    rejected: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n_classes, class_names = self.labels.num_classes, self.labels.names
        if n_classes > MAX_HIERARCHY_CLASSES:
            raise ValueError(f"a class hierarchy supports at most {MAX_HIERARCHY_CLASSES} classes, "
                             f"the label set {self.labels.name!r} has {n_classes}")
        if tuple(self.nodes[:n_classes]) != class_names:
            raise ValueError(f"the first {n_classes} nodes must be the classes {class_names}")
        if len(set(self.nodes)) != len(self.nodes):
            raise ValueError(f"node names must be unique, got {self.nodes}")
        if len(self.parents) != len(self.nodes):
            raise ValueError("one parent per node is needed")
        roots = [i for i, p in enumerate(self.parents) if p == -1]
        if len(roots) != 1:
            raise ValueError(f"the hierarchy needs exactly one root, got {[self.nodes[i] for i in roots]}")
        paths = [self._path_to_root(i) for i in range(len(self.nodes))]
        for i in range(n_classes, len(self.nodes)):
            if i not in self.parents:
                raise ValueError(f"inner node {self.nodes[i]!r} has no children")
        for i in range(n_classes):
            if i in self.parents:
                raise ValueError(f"class {self.nodes[i]!r} must be a leaf")

        table = np.empty(2**n_classes, dtype=np.int16)
        for m in range(2**n_classes):
            leaves = [k for k in range(n_classes) if m >> k & 1]
            if not leaves:
                table[m] = roots[0]
                continue
            common = set(paths[leaves[0]])
            for k in leaves[1:]:
                common &= set(paths[k])
            # The LCA is the deepest common ancestor: the first one met on a leaf's way up.
            table[m] = next(a for a in paths[leaves[0]] if a in common)
        under = [[k for k in range(n_classes) if i in paths[k]] for i in range(len(self.nodes))]
        rejected = np.array([bool(self.labels.forbidden_lut[leaves].any()) for leaves in under], dtype=bool)
        table.setflags(write=False)
        rejected.setflags(write=False)
        object.__setattr__(self, "root", roots[0])
        object.__setattr__(self, "lca_table", table)
        object.__setattr__(self, "rejected", rejected)

    def _path_to_root(self, node: int) -> list[int]:
        path = [node]
        while self.parents[path[-1]] != -1:
            parent = self.parents[path[-1]]
            if parent in path or not 0 <= parent < len(self.nodes):
                raise ValueError(f"the hierarchy has a cycle or a bad parent at {self.nodes[path[-1]]!r}")
            path.append(parent)
        return path

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_mapping(cls, root: str, children: Mapping[str, Sequence[str]], *,
                     labels: LabelSet) -> ClassHierarchy:
        """Build from a root name and ``{parent: [children]}``; every class of ``labels`` must be a leaf, once."""
        class_names = labels.names
        names = list(class_names)
        parent_of: dict[str, str] = {}
        for parent, kids in children.items():
            if isinstance(kids, str) or not isinstance(kids, Sequence):
                raise ValueError(f"children of {parent!r} must be a list of names, got {kids!r}")
            for kid in kids:
                if kid in parent_of:
                    raise ValueError(f"node {kid!r} has two parents ({parent_of[kid]!r} and {parent!r})")
                parent_of[str(kid)] = str(parent)
        inner = [root] + [p for p in children if p != root]
        for kid in parent_of:
            if kid not in names and kid not in inner:
                raise ValueError(
                    f"node {kid!r} is neither a class {class_names} nor an inner node with children"
                )
        missing = [c for c in class_names if c not in parent_of]
        if missing:
            raise ValueError(f"classes missing from the hierarchy: {missing}")
        if root in parent_of:
            raise ValueError(f"the root {root!r} cannot have a parent")
        for p in inner:
            if p != root and p not in parent_of:
                raise ValueError(f"inner node {p!r} is not reachable from the root {root!r}")
        names += [p for p in inner if p not in names]
        index = {n: i for i, n in enumerate(names)}
        parents = tuple(-1 if n == root else index[parent_of[n]] for n in names)
        return cls(nodes=tuple(names), parents=parents, labels=labels)

    @classmethod
    def from_yaml(cls, path: str | Path, *, labels: LabelSet) -> ClassHierarchy:
        """Load a hierarchy file: ``root: NAME`` and ``children: {parent: [children]}``."""
        text = Path(path).read_text(encoding="utf-8")
        return cls._from_text(text, str(path), labels=labels)

    @classmethod
    def _from_text(cls, text: str, source: str, *, labels: LabelSet) -> ClassHierarchy:
        data = safeyaml.safe_load(text)
        if not isinstance(data, dict) or "root" not in data or not isinstance(data.get("children"), dict):
            raise ValueError(f"{source}: a hierarchy needs 'root: NAME' and 'children: {{parent: [...]}}'")
        try:
            return cls.from_mapping(str(data["root"]), data["children"], labels=labels)
        except ValueError as err:
            raise ValueError(f"{source}: {err}") from None

    # -- labelling -----------------------------------------------------------------------------
    def label(self, scores: np.ndarray, tau: float) -> np.ndarray:
        """Node id of each pixel: the LCA of its classes with a score strictly above ``tau``.

        Parameters
        ----------
        scores : ndarray of shape (num_classes, ...), float
            Per-class scores (softmax, or the MCD score ``mu + 3 sigma``).
        tau : float
            Threshold.

        Returns
        -------
        ndarray of shape (...), int16
        """
        scores = np.asarray(scores)
        n_classes = self.labels.num_classes
        if scores.ndim < 1 or scores.shape[0] != n_classes:
            raise ValueError(f"scores must have shape ({n_classes}, ...), got {scores.shape}")
        bits = np.zeros(scores.shape[1:], dtype=np.uint16)
        for k in range(n_classes):
            bits |= (scores[k] > tau).astype(np.uint16) << k
        return self.lca_table[bits]

    def names(self, node_ids: np.ndarray) -> np.ndarray:
        """Node names for an array of node ids (for tests, overlays and reasons)."""
        return np.asarray(self.nodes, dtype=object)[np.asarray(node_ids)]

    def node_id(self, name: str) -> int:
        try:
            return self.nodes.index(name)
        except ValueError:
            raise ValueError(f"no node {name!r} in the hierarchy {self.nodes}") from None

    @property
    def rejected_names(self) -> tuple[str, ...]:
        return tuple(n for n, r in zip(self.nodes, self.rejected, strict=True) if r)


def default_hierarchy(labels: LabelSet) -> ClassHierarchy:
    """A label set's tree, built once per set.

    UAVid (the default): the shipped ``el/monitors/hierarchy.yaml``. Another set: its own
    ``hierarchy`` when it has one, else ``any -> {safe, unsafe}`` with the safe and the forbidden
    classes under them (the shape of the shipped tree).
    """
    return _hierarchy_of(labels)


@lru_cache(maxsize=16)
def _hierarchy_of(labels: LabelSet) -> ClassHierarchy:
    if labels == UAVID:
        text = resources.files("el.monitors").joinpath(HIERARCHY_FILE).read_text(encoding="utf-8")
        return ClassHierarchy._from_text(text, f"el/monitors/{HIERARCHY_FILE}", labels=UAVID)
    if labels.hierarchy is not None:
        return ClassHierarchy.from_mapping(labels.hierarchy["root"], labels.hierarchy["children"], labels=labels)
    inner = ("any", "safe", "unsafe")
    taken = [n for n in inner if n in labels.names]
    if taken:
        raise ValueError(f"label set {labels.name!r} has classes named {taken}: give it a 'hierarchy' for CH")
    return ClassHierarchy.from_mapping("any", {
        "any": ["safe", "unsafe"],
        "safe": [labels.names[i] for i in labels.safe_ids],
        "unsafe": [labels.names[i] for i in labels.forbidden_ids],
    }, labels=labels)
