"""Joints of a medial object (medial-surface paper, section 3.4).

A plane cuts the skeleton of one section into two; the bone points of each surface vertex go to
the side its skeletal point lies on. Every cut has a pivot (on or near the plane) that both new
sections rotate about. Cuts are applied in order and each cuts a current leaf, so the sections form
a binary tree whose root is the whole object. Rotating a section rotates everything below it in
the tree, after its own descendants' rotations (forward kinematics).

A section's angle is a scalar [rad] about its cut's `axis`, or a (3,) rotation vector [rad] in the
object's rest frame.

Pure data and array functions; ``characters.medial`` calls them.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from os import PathLike
from typing import Mapping, Sequence

import numpy as np
from numba import njit

JOINTS_FORMAT = "mop.medial_joints/1"

#: a pivot may sit off its cutting plane by at most this fraction of the cut section's size
PIVOT_TOLERANCE = 0.15


def _vector3(value, what: str) -> np.ndarray:
    from characters.sidecar import point
    return np.asarray(point(value, what, 3), dtype=np.float64)


def _unit3(value, what: str) -> np.ndarray:
    array = _vector3(value, what)
    largest = float(np.max(np.abs(array)))
    if largest > 0:
        array = array / largest     # a direction: scaled first, so 1e308 does not overflow
    norm = float(np.linalg.norm(array))
    if norm < 1e-12:
        raise ValueError(f"{what} must be a non-zero vector, got {value!r}")
    return array / norm


@dataclass(frozen=True)
class JointCut:
    """One cut: split section `section` by the plane (point, normal) into two named sections.

    section : str                 the section to cut: the root for the first cut, else a leaf
    names : (str, str)            (the section behind the plane, the one the normal points into)
    point : (3,) float [mesh units]   a point on the cutting plane
    normal : (3,) float           plane normal (normalised on use)
    axis : (3,) float             rotation axis of scalar angles for both new sections
    pivot : (3,) float | None [mesh units]  rotation centre; None = the middle of the cut
            (skeletal points near the plane, averaged and projected onto it)
    """

    section: str
    names: tuple[str, str]
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    axis: tuple[float, float, float]
    pivot: tuple[float, float, float] | None = None

    @classmethod
    def from_dict(cls, data: Mapping, *, where: str = "joint cut") -> "JointCut":
        if not isinstance(data, Mapping):
            raise TypeError(f"{where} must be a mapping, got {type(data).__name__}")
        known = {"section", "names", "point", "normal", "axis", "pivot"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"{where} has unknown keys {sorted(unknown)}; expected "
                             f"{sorted(known)}")
        missing = {"section", "names", "point", "normal", "axis"} - set(data)
        if missing:
            raise ValueError(f"{where} is missing {sorted(missing)}")
        names = data["names"]
        if (not isinstance(names, Sequence) or isinstance(names, str) or len(names) != 2
                or not all(isinstance(n, str) and n for n in names)):
            raise ValueError(f"{where}: names must be two non-empty strings, got {names!r}")
        if not isinstance(data["section"], str) or not data["section"]:
            raise ValueError(f"{where}: section must be a non-empty string, got "
                             f"{data['section']!r}")
        pivot = data.get("pivot")
        return cls(
            section=data["section"], names=(names[0], names[1]),
            point=tuple(_vector3(data["point"], f"{where}: point")),
            normal=tuple(_unit3(data["normal"], f"{where}: normal")),
            axis=tuple(_unit3(data["axis"], f"{where}: axis")),
            pivot=None if pivot is None else tuple(_vector3(pivot, f"{where}: pivot")))

    def to_dict(self) -> dict:
        out = {"section": self.section, "names": list(self.names),
               "point": [float(v) for v in self.point], "normal": [float(v) for v in self.normal],
               "axis": [float(v) for v in self.axis]}
        if self.pivot is not None:
            out["pivot"] = [float(v) for v in self.pivot]
        return out


@dataclass(frozen=True)
class JointSpec:
    """A joint definition: the root section's name and the cuts, in order (the JSON sidecar)."""

    root: str = "body"
    cuts: tuple[JointCut, ...] = ()
    extras: Mapping | None = None   # other keys of the file (material, constraint, demo hints)

    @classmethod
    def from_dict(cls, data: Mapping, *, where: str = "joints") -> "JointSpec":
        if not isinstance(data, Mapping):
            raise TypeError(f"{where} must be a mapping, got {type(data).__name__}")
        fmt = data.get("format", JOINTS_FORMAT)
        if fmt != JOINTS_FORMAT:
            raise ValueError(f"{where}: format must be {JOINTS_FORMAT!r}, got {fmt!r}")
        root = data.get("root", "body")
        if not isinstance(root, str) or not root:
            raise ValueError(f"{where}: root must be a non-empty string, got {root!r}")
        cuts = data.get("cuts", [])
        if not isinstance(cuts, Sequence) or isinstance(cuts, str):
            raise ValueError(f"{where}: cuts must be a list, got {type(cuts).__name__}")
        extras = {k: v for k, v in data.items() if k not in ("format", "root", "cuts")}
        return cls(root=root, cuts=tuple(
            JointCut.from_dict(cut, where=f"{where}: cut {k}") for k, cut in enumerate(cuts)),
            extras=extras)

    def to_dict(self) -> dict:
        out = {"format": JOINTS_FORMAT, "root": self.root,
               "cuts": [cut.to_dict() for cut in self.cuts]}
        out.update(self.extras or {})
        return out

    @classmethod
    def load(cls, path) -> "JointSpec":
        from characters.sidecar import read_json
        return cls.from_dict(read_json(path, "joints file"), where=str(path))

    def save(self, path) -> None:
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(self.to_dict(), handle, indent=2)
            handle.write("\n")

    @classmethod
    def coerce(cls, joints) -> "JointSpec":
        """JointSpec | path | dict | sequence of JointCut/dicts | None -> JointSpec."""
        if joints is None:
            return cls()
        if isinstance(joints, JointSpec):
            return joints
        if isinstance(joints, (str, PathLike)):
            return cls.load(joints)
        if isinstance(joints, Mapping):
            return cls.from_dict(joints)
        if isinstance(joints, Sequence):
            cuts = tuple(cut if isinstance(cut, JointCut) else JointCut.from_dict(
                cut, where=f"joints[{k}]") for k, cut in enumerate(joints))
            return cls(cuts=cuts)
        raise TypeError("joints must be None, a JointSpec, a path to a joints JSON file, a dict "
                        f"or a list of JointCut, got {type(joints).__name__}")


@dataclass(frozen=True)
class JointTree:
    """Built sections. S sections; index 0 is the root.

    names : (S,) str; parent : (S,) int (-1 for the root); children : (S, 2) int (-1 for leaves)
    pivot : (S, 3) float [mesh units]; axis : (S, 3) float unit (zeros for the root)
    section_of_vertex : (V,) int      the leaf section each surface vertex's bones belong to
    """

    names: tuple[str, ...]
    parent: np.ndarray
    children: np.ndarray
    pivot: np.ndarray
    axis: np.ndarray
    section_of_vertex: np.ndarray

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Every section but the root: the names a medial object's step accepts."""
        return self.names[1:]

    def descendants_mask(self, section: int) -> np.ndarray:
        """(S,) bool: `section` and everything below it."""
        mask = np.zeros(len(self.names), dtype=bool)
        stack = [section]
        while stack:
            node = stack.pop()
            mask[node] = True
            stack.extend(int(c) for c in self.children[node] if c >= 0)
        return mask

    def vertices_of(self, name: str) -> np.ndarray:
        """(K,) int surface vertices whose bones move with section `name` (and its subtree)."""
        index = self.names.index(name)
        return np.flatnonzero(self.descendants_mask(index)[self.section_of_vertex])


def build_joint_tree(spec: JointSpec, skeleton: np.ndarray, *, edge_length: float) -> JointTree:
    """Classify skeletal points by the cuts of `spec`.

    skeleton : (V, 3) float [mesh units]   skeletal points, one per surface vertex
    edge_length : float [mesh units]       mean surface edge length (sets the default pivot band)
    Raises ValueError for a cut of an unknown or already-cut section, duplicate names, a plane that
    misses the section, or a pivot far from its plane.
    """
    names = [spec.root]
    parent = [-1]
    children = [[-1, -1]]
    pivots = [np.zeros(3)]
    axes = [np.zeros(3)]
    section_of = np.zeros(len(skeleton), dtype=np.int64)
    for k, cut in enumerate(spec.cuts):
        where = f"joint cut {k} ({cut.section} -> {cut.names[0]}, {cut.names[1]})"
        if cut.section not in names:
            raise ValueError(f"{where}: no section named {cut.section!r}; sections so far: {names}")
        index = names.index(cut.section)
        if children[index][0] >= 0:
            raise ValueError(f"{where}: section {cut.section!r} is already cut in two; cut one of "
                             f"its parts {[names[c] for c in children[index]]} instead")
        for name in cut.names:
            if name in names:
                raise ValueError(f"{where}: section name {name!r} is already used; names must be "
                                 "unique")
        if cut.names[0] == cut.names[1]:
            raise ValueError(f"{where}: the two new sections need different names")
        members = np.flatnonzero(section_of == index)
        point = np.asarray(cut.point, dtype=np.float64)
        normal = _unit3(cut.normal, f"{where}: normal")
        side = (skeleton[members] - point) @ normal
        front = side > 0.0
        if front.all() or not front.any():
            raise ValueError(
                f"{where}: the plane through {point.round(4).tolist()} with normal "
                f"{normal.round(4).tolist()} misses section {cut.section!r}: all its "
                f"{len(members)} skeletal points lie on one side")
        size = float(np.linalg.norm(np.ptp(skeleton[members], axis=0))) or 1.0
        if cut.pivot is None:
            band = np.abs(side) <= max(1.5 * edge_length, np.partition(
                np.abs(side), min(len(side) - 1, 10))[min(len(side) - 1, 10)])
            centre = skeleton[members][band].mean(axis=0)
            pivot = centre - ((centre - point) @ normal) * normal
        else:
            pivot = np.asarray(cut.pivot, dtype=np.float64)
            off_plane = abs(float((pivot - point) @ normal))
            if off_plane > PIVOT_TOLERANCE * size:
                raise ValueError(
                    f"{where}: pivot {pivot.round(4).tolist()} is {off_plane:.4g} from the cutting "
                    f"plane; expected at most {PIVOT_TOLERANCE:g} x the section size "
                    f"({PIVOT_TOLERANCE * size:.4g}) - put the pivot on the plane")
            low = skeleton[members].min(axis=0) - 0.5 * size
            high = skeleton[members].max(axis=0) + 0.5 * size
            if np.any(pivot < low) or np.any(pivot > high):
                raise ValueError(
                    f"{where}: pivot {pivot.round(4).tolist()} lies far outside section "
                    f"{cut.section!r} (its skeleton spans "
                    f"{skeleton[members].min(0).round(4).tolist()} to "
                    f"{skeleton[members].max(0).round(4).tolist()})")
        axis = _unit3(cut.axis, f"{where}: axis")
        first = len(names)
        for _offset, name in enumerate(cut.names):
            names.append(name)
            parent.append(index)
            children.append([-1, -1])
            pivots.append(pivot)
            axes.append(axis)
        children[index] = [first, first + 1]
        section_of[members[~front]] = first
        section_of[members[front]] = first + 1
    return JointTree(names=tuple(names), parent=np.asarray(parent, dtype=np.int64),
                     children=np.asarray(children, dtype=np.int64),
                     pivot=np.asarray(pivots), axis=np.asarray(axes),
                     section_of_vertex=section_of)


def rotation_matrix(rotation_vector: np.ndarray) -> np.ndarray:
    """(3, 3) rotation for a rotation vector (3,) [rad] (Rodrigues)."""
    angle = float(np.linalg.norm(rotation_vector))
    if angle < 1e-15:
        return np.eye(3)
    k = rotation_vector / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * (cross @ cross)


def section_transforms(tree: JointTree, rotation_vectors: np.ndarray, rotations: np.ndarray,
                       translations: np.ndarray) -> None:
    """World transforms x -> R x + t of every section from its local rotation.

    rotation_vectors : (S, 3) float [rad]  each section's rotation about its pivot, rest frame
    rotations : (S, 3, 3) float, translations : (S, 3) float [mesh units]: written in place
    """
    _section_transforms(tree.parent, tree.pivot, np.ascontiguousarray(rotation_vectors),
                        rotations, translations)


@njit(cache=True)
def _section_transforms(parent, pivot, rotation_vectors, rotations, translations):
    # parents come before children (cuts append sections), so one forward pass suffices
    local = np.empty((3, 3))
    for s in range(parent.shape[0]):
        wx, wy, wz = rotation_vectors[s, 0], rotation_vectors[s, 1], rotation_vectors[s, 2]
        angle = np.sqrt(wx * wx + wy * wy + wz * wz)
        if angle < 1e-15:
            for a in range(3):
                for b in range(3):
                    local[a, b] = 1.0 if a == b else 0.0
        else:
            kx, ky, kz = wx / angle, wy / angle, wz / angle
            sin, cos1 = np.sin(angle), 1.0 - np.cos(angle)
            local[0, 0] = 1.0 - cos1 * (ky * ky + kz * kz)
            local[1, 1] = 1.0 - cos1 * (kx * kx + kz * kz)
            local[2, 2] = 1.0 - cos1 * (kx * kx + ky * ky)
            local[0, 1] = -sin * kz + cos1 * kx * ky
            local[1, 0] = sin * kz + cos1 * kx * ky
            local[0, 2] = sin * ky + cos1 * kx * kz
            local[2, 0] = -sin * ky + cos1 * kx * kz
            local[1, 2] = -sin * kx + cos1 * ky * kz
            local[2, 1] = sin * kx + cos1 * ky * kz
        p = parent[s]
        # local part: x -> L (x - pivot) + pivot = L x + (pivot - L pivot)
        for a in range(3):
            offset = pivot[s, a]
            for b in range(3):
                offset -= local[a, b] * pivot[s, b]
            if p < 0:
                translations[s, a] = offset
            for b in range(3):
                if p < 0:
                    rotations[s, a, b] = local[a, b]
        if p >= 0:
            # world = parent o local: R = Rp L, t = Rp (pivot - L pivot) + tp
            for a in range(3):
                t = translations[p, a]
                for b in range(3):
                    value = 0.0
                    for c in range(3):
                        value += rotations[p, a, c] * local[c, b]
                    rotations[s, a, b] = value
                    off_b = pivot[s, b]
                    for c in range(3):
                        off_b -= local[b, c] * pivot[s, c]
                    t += rotations[p, a, b] * off_b
                translations[s, a] = t


@njit(cache=True)
def transform_by_section(rest, section, rotations, translations, out):
    """out[i] = R[section[i]] rest[i] + t[section[i]]; rest, out : (B, 3), section : (B,) int."""
    for i in range(rest.shape[0]):
        s = section[i]
        for a in range(3):
            out[i, a] = (rotations[s, a, 0] * rest[i, 0] + rotations[s, a, 1] * rest[i, 1]
                         + rotations[s, a, 2] * rest[i, 2] + translations[s, a])


@njit(cache=True)
def carry_nodes(rest, section, nodes, rotations, translations, x, v, inverse_h):
    """Move kinematic nodes to their posed rest: x[nodes[k]] = R rest[k] + t, v = motion / h.

    rest : (K, 3) float, section : (K,) int, nodes : (K,) int; x, v : (N, 3) float, written.
    """
    for k in range(nodes.shape[0]):
        i = nodes[k]
        s = section[k]
        for a in range(3):
            goal = (rotations[s, a, 0] * rest[k, 0] + rotations[s, a, 1] * rest[k, 1]
                    + rotations[s, a, 2] * rest[k, 2] + translations[s, a])
            v[i, a] = (goal - x[i, a]) * inverse_h
            x[i, a] = goal
