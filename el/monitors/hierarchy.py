"""The CH monitor's classification hierarchy, loaded from ``hierarchy.yaml`` (data, not code).

A pixel is labelled with the closest common ancestor (LCA) of the classes whose score exceeds tau.
With up to :data:`LCA_TABLE_MAX_CLASSES` classes a pixel's "classes above tau" is a bit mask, so the LCA
of every possible mask is precomputed once (256 entries for UAVid's 8 classes) and labelling a patch is
a table look-up (docs/architecture.md section 3.6). A larger label set (the 23 classes of
``semantic_drone``) would need a table of 2**23 entries or more, so the LCA is found for each distinct
"classes above tau" pattern of the pixels (few in a disc): the deepest node holding all of its classes.
Both ways give the same node.

Node ids: the leaves keep their class ids (0..C-1, el/classes/labels.py); inner nodes follow (C, C+1, ...).

A hierarchy belongs to a label set (``labels``): its classes are the leaves. :func:`default_hierarchy`
gives the set's own tree: the shipped file for UAVid, the tree the set declares, else one derived from
its forbidden/safe split.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from el.base import safeyaml, userfiles
from el.classes.labels import UAVID, LabelSet

HIERARCHY_FILE = "hierarchy.yaml"
SHIPPED_TREES = {UAVID: HIERARCHY_FILE}
"""Label sets whose tree is a file of this package (the shipped UAVid set: the paper's Fig. 3)."""
LCA_TABLE_MAX_CLASSES = 16  # up to here a pixel's classes above tau are a 16-bit mask into a 2**n LCA table
DERIVED_INNER = ("any", "safe", "unsafe")  # the inner nodes of a derived tree (renamed if a class has the name)


@dataclass(frozen=True, eq=False)
class ClassHierarchy:
    """A class tree over a label set's classes, with its LCA look-up and the nodes a monitor rejects.

    Parameters
    ----------
    nodes : tuple of str
        Node names; ``nodes[i]`` is node id ``i``. The first ``num_classes`` are the classes, in
        class-id order.
    parents : tuple of int
        Parent node id of each node, ``-1`` for the root.
    labels : LabelSet
        The label set whose classes are the leaves (any number of classes).

    Attributes
    ----------
    root : int
        The root's node id (the label of a pixel with no class above tau).
    lca_table : ndarray of shape (2**num_classes,), int16, or None
        ``lca_table[m]`` is the LCA of the classes whose bits are set in ``m`` (the root for ``m = 0``);
        None above :data:`LCA_TABLE_MAX_CLASSES` classes (:meth:`label` then works per distinct pattern).
    rejected : ndarray of shape (len(nodes),), bool
        True for nodes with a forbidden class under them (the root, ``unsafe`` and the forbidden
        leaves with the shipped tree): a disc pixel with such a label makes CH reject.
    """

    nodes: tuple[str, ...]
    parents: tuple[int, ...]
    labels: LabelSet = field(repr=False)
    root: int = field(init=False)
    lca_table: np.ndarray | None = field(init=False, repr=False)
    rejected: np.ndarray = field(init=False, repr=False)
    under: np.ndarray = field(init=False, repr=False)
    under_words: np.ndarray = field(init=False, repr=False)
    depth: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.labels, LabelSet):
            raise ValueError(f"labels must be a LabelSet, got {type(self.labels).__name__}")
        n_classes, class_names = self.labels.num_classes, self.labels.names
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

        table = _lca_table(paths, n_classes, roots[0]) if n_classes <= LCA_TABLE_MAX_CLASSES else None
        # under[i, k]: class k lies under node i; depth[i]: edges from node i up to the root
        under = np.array([[i in paths[k] for k in range(n_classes)] for i in range(len(self.nodes))], dtype=bool)
        depth = np.array([len(p) - 1 for p in paths], dtype=np.int32)
        rejected = np.array([bool(self.labels.forbidden_lut[row].any()) for row in under], dtype=bool)
        words = _pack_classes(under.T)  # (nodes, W): the classes under each node, packed as a pixel's
        for a in (table, under, words, depth, rejected):
            if a is not None:
                a.setflags(write=False)
        object.__setattr__(self, "root", roots[0])
        object.__setattr__(self, "lca_table", table)
        object.__setattr__(self, "rejected", rejected)
        object.__setattr__(self, "under", under)
        object.__setattr__(self, "under_words", words)
        object.__setattr__(self, "depth", depth)

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
        """Load a hierarchy file: ``root: NAME`` and ``children: {parent: [children]}``, read through the bounded
        reader (``el.base.userfiles``: a regular file of at most 1 MiB; a FIFO or a device refused before any read)."""
        text = userfiles.read_text(path, what="hierarchy file", max_bytes=safeyaml.MAX_YAML_BYTES)
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
        if self.lca_table is None:
            return self._label_by_masks(scores > tau)
        bits = np.zeros(scores.shape[1:], dtype=np.uint16)
        for k in range(n_classes):
            bits |= (scores[k] > tau).astype(np.uint16) << k
        return self.lca_table[bits]

    def _label_by_masks(self, above: np.ndarray) -> np.ndarray:
        """The LCA of each pixel's classes above tau, ``above`` (C, ...) bool, without a 2**C table.

        Each pixel's classes are packed into 64-bit words; for each distinct pattern (few in a disc) the LCA is
        the deepest node whose classes hold all of the pattern's (they form a chain from the root, so it is
        unique), the root for a pixel with none; pixels then take their pattern's node.
        """
        words = _pack_classes(above.reshape(above.shape[0], -1))  # (P, W)
        if words.shape[1] == 1:  # up to 64 classes: a 1-D unique, far faster than unique rows
            patterns, inverse = np.unique(words[:, 0], return_inverse=True)
            patterns = patterns[:, None]
        else:
            patterns, inverse = np.unique(words, axis=0, return_inverse=True)  # (K, W), (P,)
        held = (self.under_words[:, None, :] & patterns[None]) == patterns[None]  # (nodes, K, W)
        covers = held.all(axis=2)
        deepest = np.where(covers, self.depth[:, None], -1).argmax(axis=0)
        lca = np.where(patterns.any(axis=1), deepest, self.root).astype(np.int16)
        return lca[inverse.reshape(-1)].reshape(above.shape[1:])

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


def _pack_classes(flags: np.ndarray) -> np.ndarray:
    """(C, P) bool -> (P, W) uint64: each column's set classes as bits, class k in word k // 64."""
    n_classes = flags.shape[0]
    words = np.zeros((flags.shape[1], (n_classes + 63) // 64), dtype=np.uint64)
    for k in range(n_classes):
        words[:, k // 64] |= flags[k].astype(np.uint64) << np.uint64(k % 64)
    return words


def _lca_table(paths: Sequence[Sequence[int]], n_classes: int, root: int) -> np.ndarray:
    """``table[m]``: the LCA of the classes whose bits are set in ``m`` (the root for ``m = 0``), (2**C,) int16."""
    table = np.empty(2**n_classes, dtype=np.int16)
    for m in range(2**n_classes):
        leaves = [k for k in range(n_classes) if m >> k & 1]
        if not leaves:
            table[m] = root
            continue
        common = set(paths[leaves[0]])
        for k in leaves[1:]:
            common &= set(paths[k])
        # The LCA is the deepest common ancestor: the first one met on a leaf's way up.
        table[m] = next(a for a in paths[leaves[0]] if a in common)
    return table


def default_hierarchy(labels: LabelSet) -> ClassHierarchy:
    """A label set's tree, built once per set, for any number of classes.

    The shipped UAVid set: ``el/monitors/hierarchy.yaml`` (:data:`SHIPPED_TREES`). Another set: its own
    ``hierarchy`` when it declares one, else ``any -> {safe, unsafe}`` with the safe and the forbidden
    classes under them (the shape of the shipped tree; an inner name a class already has is suffixed
    with ``_node``). ValueError naming the set when its declared tree is not over its classes.
    """
    if not isinstance(labels, LabelSet):
        raise ValueError(f"labels must be a LabelSet, got {type(labels).__name__}")
    return _hierarchy_of(labels)


@lru_cache(maxsize=16)
def _hierarchy_of(labels: LabelSet) -> ClassHierarchy:
    shipped = SHIPPED_TREES.get(labels)
    if shipped is not None:
        text = resources.files("el.monitors").joinpath(shipped).read_text(encoding="utf-8")
        return ClassHierarchy._from_text(text, f"el/monitors/{shipped}", labels=labels)
    if labels.hierarchy is not None:
        try:
            return ClassHierarchy.from_mapping(labels.hierarchy["root"], labels.hierarchy["children"],
                                               labels=labels)
        except ValueError as err:
            raise ValueError(f"label set {labels.name!r}: its hierarchy: {err}") from None
    any_, safe, unsafe = (_free_name(n, labels.names) for n in DERIVED_INNER)
    return ClassHierarchy.from_mapping(any_, {
        any_: [safe, unsafe],
        safe: [labels.names[i] for i in labels.safe_ids],
        unsafe: [labels.names[i] for i in labels.forbidden_ids],
    }, labels=labels)


def _free_name(name: str, taken: Sequence[str]) -> str:
    """``name``, or ``name_node`` (``name_node_node``, ...) when a class is called that already."""
    while name in taken:
        name += "_node"
    return name
