"""Finger regions (paper section 6): five marked vertex sets that the glove's fingers pull.

A region is given on the visual mesh, by vertex indices or by a centre and radius, in a small
JSON sidecar file or as a dict; each says how the region moves when its finger opens fully
("open": a rotation about a hinge axis, or a translation). Sidecar layout:

    {"format": "mop.latex-regions", "version": 1,
     "regions": {
        "thumb": {"vertices": [12, 13, 40], "open": {"rotate": {"origin": [0, -0.01, -0.03],
                                                                "axis": [1, 0, 0], "degrees": 20}}},
        "index": {"center": [0.06, 0.0, 0.08], "radius": 0.015,
                  "open": {"translate": [0, 0.02, 0]}},
        ...},
     "landmarks": {"upper_lip": [101], "lower_lip": [202]}}

Vertex indices refer to the mesh file as stored (before duplicate vertices are merged). Region
names are finger names; "landmarks" are optional named vertex sets used for measurements (e.g.
the mouth gap). Regions must be disjoint and made of adjacent vertices.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
SIDECAR_FORMAT = "mop.latex-regions"


@dataclass(frozen=True)
class Opening:
    """How a region moves at full opening (bend 1): rotate about an axis or translate.

    rotate: origin (3,) [m], axis (3,) unit, degrees; translate: offset (3,) [m]."""

    kind: str
    origin: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (1.0, 0.0, 0.0)
    degrees: float = 0.0
    offset: tuple = (0.0, 0.0, 0.0)

    def apply(self, points: np.ndarray, amount: float, out: np.ndarray | None = None) -> np.ndarray:
        """points (P, 3) [m] moved by `amount` (0 = rest, 1 = fully open); writes into out."""
        if out is None:
            out = np.empty_like(points)
        if self.kind == "translate":
            np.add(points, np.asarray(self.offset) * amount, out=out)
            return out
        angle = math.radians(self.degrees) * amount
        axis = np.asarray(self.axis)
        origin = np.asarray(self.origin)
        c, s = math.cos(angle), math.sin(angle)
        x, y, z = axis
        t = 1 - c  # Rodrigues' rotation about the unit axis (x, y, z)
        rotation = np.array([[c + x * x * t, x * y * t - z * s, x * z * t + y * s],
                             [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
                             [z * x * t - y * s, z * y * t + x * s, c + z * z * t]])
        np.matmul(points - origin, rotation.T, out=out)
        out += origin
        return out

    def to_dict(self) -> dict:
        if self.kind == "translate":
            return {"translate": list(self.offset)}
        return {"rotate": {"origin": list(self.origin), "axis": list(self.axis),
                           "degrees": self.degrees}}


def _vector(value, what: str) -> tuple:
    from characters.sidecar import point
    return point(value, what, 3)


def parse_opening(value, what: str) -> Opening | None:
    if value is None:
        return None
    if not isinstance(value, Mapping) or len(value) != 1:
        raise ValueError(f"{what}: 'open' must be {{'rotate': {{...}}}} or "
                         f"{{'translate': [x, y, z]}}, got {value!r}")
    (kind, body), = value.items()
    if kind == "translate":
        return Opening("translate", offset=_vector(body, f"{what}: open.translate"))
    if kind == "rotate":
        if not isinstance(body, Mapping) or set(body) - {"origin", "axis", "degrees"}:
            raise ValueError(f"{what}: open.rotate takes origin, axis and degrees, got {body!r}")
        axis = np.asarray(_vector(body.get("axis", (1, 0, 0)), f"{what}: open.rotate.axis"))
        axis = axis / max(float(np.max(np.abs(axis))), 1e-300)   # no overflow in the norm
        if np.linalg.norm(axis) == 0:
            raise ValueError(f"{what}: open.rotate.axis must not be zero")
        degrees = body.get("degrees")
        if isinstance(degrees, bool) or not isinstance(degrees, (int, float)):
            raise ValueError(f"{what}: open.rotate.degrees must be a number, got {degrees!r}")
        return Opening("rotate", origin=_vector(body.get("origin", (0, 0, 0)),
                                                 f"{what}: open.rotate.origin"),
                       axis=tuple(axis / np.linalg.norm(axis)), degrees=float(degrees))
    raise ValueError(f"{what}: 'open' must be 'rotate' or 'translate', got {kind!r}")


@dataclass
class RegionSpec:
    """A region as the user gave it: vertices (input numbering) or centre + radius [m]."""

    name: str
    vertices: np.ndarray | None = None
    center: tuple | None = None
    radius: float | None = None
    opening: Opening | None = None


def _parse_one(name: str, value, source: str) -> RegionSpec:
    what = f"{source}: finger region {name!r}"
    if name not in FINGERS:
        raise ValueError(f"{source}: unknown finger region {name!r}; the regions are the glove's "
                         f"fingers {FINGERS}")
    if isinstance(value, Mapping):
        unknown = set(value) - {"vertices", "center", "radius", "open"}
        if unknown:
            raise ValueError(f"{what} has unknown key(s) {sorted(unknown)}; expected vertices or "
                             f"center + radius, and optionally open")
        opening = parse_opening(value.get("open"), what)
        if "vertices" in value:
            if "center" in value:
                raise ValueError(f"{what}: give either vertices or center + radius, not both")
            return RegionSpec(name, _indices(value["vertices"], what), opening=opening)
        if "center" not in value or "radius" not in value:
            raise ValueError(f"{what}: expected 'vertices' or 'center' and 'radius'")
        radius = value["radius"]
        if isinstance(radius, bool) or not isinstance(radius, (int, float)) or not radius > 0 \
                or not math.isfinite(radius):
            raise ValueError(f"{what}: radius must be a length > 0 [m], got {radius!r}")
        return RegionSpec(name, center=_vector(value["center"], f"{what}: center"),
                          radius=float(radius), opening=opening)
    return RegionSpec(name, _indices(value, what))


def _indices(value, what: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        if value.ndim != 1 or value.size == 0 or not np.issubdtype(value.dtype, np.integer):
            raise TypeError(f"{what}: vertices must be a non-empty 1-D integer array, got "
                            f"{value.dtype} {value.shape}")
        return value.astype(np.int64)
    from characters.sidecar import indices
    return indices(list(value) if isinstance(value, (range, set, frozenset)) else value,
                   f"{what}: vertices")


def parse_regions(spec, *, source: str = "finger_regions"):
    """Region specs from a sidecar path, a dict {finger: spec} or a full sidecar dict.
    Returns ({finger: RegionSpec} in finger order, {landmark: (L,) int64 input indices})."""
    landmarks: dict[str, np.ndarray] = {}
    if isinstance(spec, (str, Path)):
        from characters.sidecar import read_json
        path = Path(spec)
        spec = read_json(path, "finger region file")
        source = str(path)
    if not isinstance(spec, Mapping):
        raise TypeError(f"{source}: finger regions must be a path, a dict {{finger: vertices or "
                        f"spec}} or None, got {type(spec).__name__}")
    if "regions" in spec:
        from characters.sidecar import check_header
        if spec.get("format", SIDECAR_FORMAT) != SIDECAR_FORMAT:
            raise ValueError(f"{source}: format must be {SIDECAR_FORMAT!r}, got "
                             f"{spec.get('format')!r}")
        check_header(spec, format=SIDECAR_FORMAT, version=1, where=source)
        marks = spec.get("landmarks") or {}
        if not isinstance(marks, Mapping):
            raise TypeError(f"{source}: 'landmarks' must map names to vertex lists")
        for name, value in marks.items():
            landmarks[str(name)] = _indices(value, f"{source}: landmark {name!r}")
        spec = spec["regions"]
        if not isinstance(spec, Mapping):
            raise ValueError(f"{source}: 'regions' must map finger names to specs")
    regions = {str(name): _parse_one(str(name), value, source) for name, value in spec.items()}
    if not regions:
        raise ValueError(f"{source}: no finger regions given; expected some of {FINGERS}")
    ordered = {name: regions[name] for name in FINGERS if name in regions}
    return ordered, landmarks


def sidecar_dict(regions: Mapping[str, RegionSpec], landmarks: Mapping[str, np.ndarray]) -> dict:
    """The JSON-ready sidecar for regions given by vertices."""
    out = {"format": SIDECAR_FORMAT, "version": 1, "regions": {}}
    for name, region in regions.items():
        entry = {"vertices": [int(i) for i in region.vertices]}
        if region.opening is not None:
            entry["open"] = region.opening.to_dict()
        out["regions"][name] = entry
    if landmarks:
        out["landmarks"] = {k: [int(i) for i in v] for k, v in landmarks.items()}
    return out


def _components(vertex_set: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    """Connected pieces of a vertex subset along the mesh edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    local = np.full(int(faces.max()) + 1, -1, dtype=np.int64)
    local[vertex_set] = np.arange(len(vertex_set))
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges = local[edges]
    edges = edges[(edges >= 0).all(1)]
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                       shape=(len(vertex_set),) * 2)
    count, labels = connected_components(graph, directed=False)
    return [vertex_set[labels == i] for i in range(count)]


def resolve_regions(specs: Mapping[str, RegionSpec], vertices: np.ndarray, faces: np.ndarray,
                    index_map: np.ndarray, distance) -> dict[str, np.ndarray]:
    """Visual vertex indices (cleaned numbering) of each region, validated.

    vertices (V, 3), faces (F, 3): the cleaned surface; index_map (V_in,): input -> cleaned
    vertex (-1 = dropped); distance: a SurfaceDistance of the surface."""
    resolved: dict[str, np.ndarray] = {}
    input_count = len(index_map)
    for name, spec in specs.items():
        what = f"finger region {name!r}"
        if spec.vertices is not None:
            bad = spec.vertices[(spec.vertices < 0) | (spec.vertices >= input_count)]
            if bad.size:
                raise ValueError(f"{what} lies outside the mesh: vertex {int(bad[0])} does not "
                                 f"exist (the mesh has {input_count} vertices)")
            mapped = index_map[spec.vertices]
            lost = int((mapped < 0).sum())
            if lost == len(mapped):
                raise ValueError(f"{what} would be lost: all {lost} of its vertices were removed "
                                 f"while cleaning the mesh (unused or degenerate faces)")
            members = np.unique(mapped[mapped >= 0])
            pieces = _components(members, faces)
            if len(pieces) > 1:
                raise ValueError(f"{what} is not made of adjacent vertices: it falls into "
                                 f"{len(pieces)} separate pieces of sizes "
                                 f"{sorted(len(p) for p in pieces)}")
        else:
            centre = np.asarray(spec.center)
            gap = float(distance(centre[None])[0])
            if gap > spec.radius:
                raise ValueError(f"{what} lies outside the mesh: its centre {list(spec.center)} "
                                 f"is {gap:.4g} m from the surface, farther than its radius "
                                 f"{spec.radius:.4g} m")
            members = np.flatnonzero(np.linalg.norm(vertices - centre, axis=1) <= spec.radius)
            if members.size == 0:
                raise ValueError(f"{what} would be lost: no vertex lies within {spec.radius:.4g} "
                                 f"m of {list(spec.center)}; use a larger radius")
            # a ball can reach two sheets (both lips): keep the piece nearest the centre
            pieces = _components(members, faces)
            if len(pieces) > 1:
                nearest = members[np.argmin(np.linalg.norm(vertices[members] - centre, axis=1))]
                members = next(p for p in pieces if nearest in p)
        resolved[name] = members
    names = list(resolved)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            shared = np.intersect1d(resolved[a], resolved[b])
            if shared.size:
                raise ValueError(f"finger regions {a!r} and {b!r} overlap in {shared.size} "
                                 f"vertices; regions must be disjoint")
    return resolved


def auto_regions(vertices: np.ndarray, radius: float) -> dict[str, RegionSpec]:
    """Regions chosen by position when none are given (+y up): the thumb at the bottom of the
    mesh, the four fingers at the top of four slabs spread across its width (x); opening pulls
    the thumb down and the fingers up by 15% of the height. The radius shrinks if needed so the
    regions stay disjoint."""
    lo, hi = vertices.min(0), vertices.max(0)
    width = float(hi[0] - lo[0])
    height = float(hi[1] - lo[1])
    slab = 0.2 * width
    radius = min(radius, 0.4 * slab)

    def band(x: float, half_width: float) -> np.ndarray:
        # vertices within the band around x, or (a mesh in pieces, a gap there) the nearest
        near = np.flatnonzero(np.abs(vertices[:, 0] - x) < half_width)
        return near if near.size else np.array([int(np.argmin(np.abs(vertices[:, 0] - x)))])

    middle = band(0.5 * (lo[0] + hi[0]), 0.5 * slab)
    centres = {"thumb": vertices[middle[np.argmin(vertices[middle, 1])]]}
    for k, name in enumerate(FINGERS[1:]):
        near = band(lo[0] + (0.2 + 0.2 * k) * width, 0.25 * slab)
        centres[name] = vertices[near[np.argmax(vertices[near, 1])]]
    # balls of a radius under half the closest two centres' distance share no vertex
    points = np.array(list(centres.values()))
    gaps = np.linalg.norm(points[:, None] - points[None], axis=2)
    closest = float(gaps[np.triu_indices(len(points), 1)].min())
    if not closest > 0:
        raise ValueError("automatic finger regions need five distinct places on the mesh (the "
                         "bottom of its middle and the tops of four slabs across its width), "
                         "and this mesh has too few distinct vertices there; give "
                         "finger_regions explicitly")
    radius = min(radius, 0.49 * closest)
    specs = {}
    for name, centre in centres.items():
        offset = (0.0, (-0.15 if name == "thumb" else 0.15) * height, 0.0)
        specs[name] = RegionSpec(name, center=tuple(centre), radius=radius,
                                 opening=Opening("translate", offset=offset))
    return specs


def default_opening(vertices: np.ndarray, faces: np.ndarray, members: np.ndarray,
                    scale: float) -> Opening:
    """Outward along the region's mean vertex normal by `scale` [m]."""
    from .surface import face_normals
    normals, areas = face_normals(vertices, faces)
    touching = np.isin(faces, members).any(1)
    n = (normals[touching] * areas[touching, None]).sum(0)
    n /= max(np.linalg.norm(n), 1e-300)
    return Opening("translate", offset=tuple(float(v) for v in n * scale))


def spread_subset(points: np.ndarray, count: int) -> np.ndarray:
    """Indices of `count` well-spread rows of points (P, 3) by farthest-point sampling, starting
    from the point nearest the centroid."""
    if count >= len(points):
        return np.arange(len(points))
    chosen = [int(np.argmin(np.linalg.norm(points - points.mean(0), axis=1)))]
    gap = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(gap))
        chosen.append(nxt)
        gap = np.minimum(gap, np.linalg.norm(points - points[nxt], axis=1))
    return np.array(sorted(chosen), dtype=np.int64)
