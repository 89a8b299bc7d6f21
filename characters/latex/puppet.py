"""Latex hand puppets (Wuethrich et al., WSCG 2006): a high-resolution visual mesh carried by a
low-resolution, three-layer tetrahedral mass-spring mesh, driven by a glove's five fingers.

    from characters import LatexPuppet
    q = LatexPuppet.froggy(masses=2000)                 # the shipped frog head
    q = LatexPuppet.from_mesh("head.ply", masses=3000)  # regions from head.json if present
    q.step(1 / 25, {"thumb": 1.0, "index": 1.0})        # finger bends: 0 rest .. 1 open
    q.surface()                                          # (V, 3) deformed visual vertices

Building (see characters/latex/): the surface is cleaned and closed, decimated with the
paper's combined quadric + roundness priority and normal-flip rejection, keeping the marked
finger regions (4.1); two fronts of biting-sphere points inside it give three node layers,
connected by Delaunay tetrahedra (4.2); each layer's springs and masses come from its material
preset; each visual vertex follows its nearest decimated vertices by the connection map
(equations 3-4). Stepping turns finger targets into target forces on the region nodes and
advances the model by one backward Euler step: projective dynamics by default (faster here,
see benchmarks/latex_puppet.py), or the paper's implicit Euler with one Newton iteration.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from ..control import Control
from ..integrators import ImplicitEuler, Integrator, ProjectiveDynamics, Verlet
from ..materials import Material, material
from ..model import MassSpring
from . import connection as _connection
from .decimate import Decimation, decimate, roundness, target_edge_length
from .layers import LAYER_NAMES, Layers, build_layers, tetrahedron_volumes
from .regions import (Opening, auto_regions, default_opening, parse_regions,
                      resolve_regions, spread_subset)
from .surface import (CleanSurface, InsideTest, SurfaceDistance, clean_surface,
                      load_mesh, signed_volume)

log = logging.getLogger(__name__)

DATA = Path(__file__).resolve().parent.parent / "assets"
FROGGY = DATA / "froggy.ply"

#: default material preset of each layer (latex skin, foam, hand cavity), characters/materials.toml
DEFAULT_MATERIALS = ("latex_skin", "latex_foam", "latex_cavity")
INTEGRATORS = ("implicit_euler", "projective_dynamics", "verlet")
#: local/global iterations of the default integrator: at 10k masses 6 iterations follow a
#: tightly solved implicit Euler step within 4 mm rms of a 10 cm mouth opening (10: 3 mm) at
#: 60% of the cost (benchmarks/latex_puppet.py, section 2b)
PD_ITERATIONS = 6
MIN_MASSES = 60

# the surface keeps about this share of the masses; the two inner fronts take the rest (the
# builder corrects the share by measuring, see _build_layers_to_count)
_SURFACE_SHARE = 0.58


@dataclass
class BuildReport:
    """What building a latex puppet did, for logs and the README's tables."""

    source: str
    repairs: list[str]
    visual_vertices: int
    visual_faces: int
    surface_nodes: int
    layer_counts: tuple
    tetrahedra: int
    springs: int
    stopped_early: bool
    surface_roundness_mean: float
    surface_roundness_min: float
    tetrahedra_volume_share: float
    seconds: dict = field(default_factory=dict)


@dataclass
class _Region:
    name: str
    nodes: np.ndarray          # (P,) int64 physical node indices (all layer 0)
    rest: np.ndarray           # (P, 3) float [m]
    centroid: np.ndarray       # (3,) float [m]
    opening: Opening
    slot: slice                # this region's rows in the target buffers


def _resolve_materials(materials) -> tuple[Material, Material, Material]:
    if materials is None:
        materials = DEFAULT_MATERIALS
    if isinstance(materials, Mapping):
        unknown = set(materials) - set(LAYER_NAMES)
        if unknown:
            raise ValueError(f"materials keys must be layer names {LAYER_NAMES}, got "
                             f"{sorted(unknown)}")
        materials = tuple(materials.get(name, default)
                          for name, default in zip(LAYER_NAMES, DEFAULT_MATERIALS))
    if isinstance(materials, (str, Material)) or len(materials) != 3:
        raise ValueError(f"materials must be three presets (latex, foam, cavity) as a sequence or "
                         f"a dict {{layer: preset}}, got {materials!r}")
    resolved = []
    for layer_name, value in zip(LAYER_NAMES, materials):
        preset = material(value)  # raises ValueError naming the known presets
        if preset.youngs_modulus is None or preset.density is None:
            raise ValueError(f"material {preset.name!r} for the {layer_name} layer has no "
                             f"youngs_modulus/density: latex puppets need volumetric presets "
                             f"(family 'latex')")
        resolved.append(preset)
    return tuple(resolved)


def _make_integrator(integrator, substeps: int) -> Integrator:
    if isinstance(integrator, Integrator):
        return integrator
    if integrator == "implicit_euler":
        return ImplicitEuler(substeps=substeps, tolerance=1e-3, max_iterations=200)
    if integrator == "projective_dynamics":
        return ProjectiveDynamics(substeps=substeps, iterations=PD_ITERATIONS)
    if integrator == "verlet":
        return Verlet(substeps=max(substeps, 200))
    raise ValueError(f"integrator must be one of {INTEGRATORS} or an Integrator, got "
                     f"{integrator!r}")


class LatexPuppet:
    """A latex hand puppet: build with `from_mesh` (or `froggy`), then `step` and `surface`.

    Attributes after building:
    model : MassSpring (node order: layer-0 surface nodes first); state : SpringState
    layer : (N,) int64: 0 latex skin, 1 foam, 2 hand cavity
    tetrahedra : (K, 4) int64, positive volume; tetrahedron_layer : (K,) int64
    surface_faces : (F_s, 3) int64 triangles of the decimated surface (nodes 0..n_s-1)
    surface_visual_index : (n_s,) int64 visual vertex of each surface node
    faces : (F, 3) int64 visual triangles; vertex_colors : (V, 4) uint8 or None
    regions : {finger: (P,) int64 node indices}; landmarks : {name: (L,) int64 visual vertices}
    connection : ConnectionMap (V x n_s weights, rows sum to one); skin : connection.Skin (the
    visual mesh from `pose()`, picklable)
    report : BuildReport
    """

    def __init__(self, *, model: MassSpring, layers: Layers, surface_faces: np.ndarray,
                 surface_visual_index: np.ndarray, visual_vertices: np.ndarray,
                 faces: np.ndarray, connection, regions: list[_Region],
                 finger_stiffness: np.ndarray, finger_damping: np.ndarray,
                 landmarks: dict, vertex_colors, integrator: Integrator, materials,
                 report: BuildReport):
        self.model = model
        self.layer = layers.layer
        self.tetrahedra = layers.tetrahedra
        self.tetrahedron_layer = layers.tetrahedron_layer
        self.spring_layer = layers.spring_layer
        self.surface_faces = surface_faces
        self.surface_visual_index = surface_visual_index
        self.rest_vertices = visual_vertices
        self.faces = faces
        self.connection = connection
        self.landmarks = landmarks
        self.vertex_colors = vertex_colors
        self.integrator = integrator
        self.materials = materials
        self.report = report
        self._regions = regions
        self.regions = {r.name: r.nodes for r in regions}
        self.openings = {r.name: r.opening for r in regions}
        self._target_index = np.concatenate([r.nodes for r in regions]).astype(np.int64)
        # one Control for every step: `step` rewrites its target rows in place
        self._control = Control(targets=(self._target_index,
                                         np.concatenate([r.rest for r in regions])),
                                target_stiffness=finger_stiffness, target_damping=finger_damping)
        self._target_position = self._control.target_position
        self._surface_count = len(surface_visual_index)
        self._node_rest = np.ascontiguousarray(model.rest_positions[:self._surface_count])
        self._visual = np.array(visual_vertices, dtype=np.float64)
        self._surface_view = self._visual.view()
        self._surface_view.setflags(write=False)
        self.skin = _connection.Skin(connection, visual_vertices, self._node_rest)
        self._skinned = True      # _visual follows the state (stepping leaves it to surface())
        self.state = model.state()

    # --- the shared puppet interface ---------------------------------------------------------
    @property
    def target_names(self) -> tuple[str, ...]:
        """The finger names `step` accepts (the regions this puppet has, in glove order)."""
        return tuple(r.name for r in self._regions)

    def reset(self) -> None:
        """Back to rest: positions at rest, zero velocity, visual mesh at rest."""
        self.state = self.model.state()
        self._visual[...] = self.rest_vertices
        self._skinned = True

    def step(self, dt: float, targets: Mapping | None = None) -> None:
        """Advance by dt [s] with finger targets {finger: value}.

        A value is a bend (float or (1,), 0 = rest .. 1 = fully open; clipped to [0, 1]) that
        moves the region along its opening, or a position (3,) [m] for the region's centroid. A
        finger absent from targets holds its region at rest (the hand stays inside the puppet)."""
        targets = {} if targets is None else targets
        if not isinstance(targets, Mapping):
            raise TypeError(f"targets must be a dict {{finger: value}}, got "
                            f"{type(targets).__name__}")
        for name in targets:
            if name not in self.regions:
                raise ValueError(f"unknown target {name!r}; this puppet's targets are "
                                 f"{self.target_names}")
        out = self._target_position
        for region in self._regions:
            value = targets.get(region.name)
            rows = out[region.slot]
            if value is None:
                rows[...] = region.rest
                continue
            array = np.asarray(value, dtype=np.float64)
            if array.shape in ((), (1,)):  # Motion.sample gives scalar channels as (1,)
                bend = float(array.reshape(()))
                if not math.isfinite(bend):
                    raise ValueError(f"target {region.name!r} must be finite, got {bend}")
                region.opening.apply(region.rest, min(max(bend, 0.0), 1.0), out=rows)
            elif array.shape == (3,):
                if not np.all(np.isfinite(array)):
                    raise ValueError(f"target {region.name!r} must be finite, got {array}")
                np.add(region.rest, array - region.centroid, out=rows)
            else:
                raise ValueError(f"target {region.name!r} must be a bend (float 0..1) or a "
                                 f"position (3,) [m], got shape {array.shape}")
        self.integrator.step(self.model, self.state, dt, self._control)
        self._skinned = False

    def surface(self) -> np.ndarray:
        """(V, 3) float [m] the deformed visual vertices now (a read-only view, updated in place
        when asked for after a step: copy it to keep it). Computed from the surface nodes when
        asked for, not by `step`: a render worker draws from `pose()` and `skin` instead."""
        if not self._skinned:
            self.skin(self.state.x, self._visual)
            self._skinned = True
        return self._surface_view

    def pose(self) -> np.ndarray:
        """(n_s, 3) float [m] the surface nodes now (a view of the state): what `skin` turns
        into the visual mesh, `skin(pose(), out)` equal to `surface()`."""
        return self.state.x[:self._surface_count]

    # --- measurements ---------------------------------------------------------------------------
    def landmark(self, name: str) -> np.ndarray:
        """(3,) float [m] current mean position of a named landmark's visual vertices."""
        if name not in self.landmarks:
            raise ValueError(f"unknown landmark {name!r}; this puppet has {sorted(self.landmarks)}")
        return self.surface()[self.landmarks[name]].mean(0)

    def mouth_gap(self) -> float:
        """Distance [m] between the upper_lip and lower_lip landmarks (puppets that have them)."""
        return float(np.linalg.norm(self.landmark("upper_lip") - self.landmark("lower_lip")))

    def __repr__(self) -> str:
        counts = np.bincount(self.layer, minlength=3)
        return (f"LatexPuppet({self.model.node_count} masses [{counts[0]} latex, {counts[1]} "
                f"foam, {counts[2]} cavity], {self.model.spring_count} springs, "
                f"{len(self.tetrahedra)} tetrahedra, {len(self.rest_vertices)} visual vertices, "
                f"targets {self.target_names})")

    # --- building -------------------------------------------------------------------------------
    @classmethod
    def froggy(cls, *, masses: int = 2000, **options) -> "LatexPuppet":
        """The shipped frog head (characters/assets/froggy.ply + froggy.json)."""
        return cls.from_mesh(FROGGY, masses=masses, **options)

    @classmethod
    def from_mesh(cls, mesh, *, masses: int = 2000, finger_regions=None, materials=None,
                  roundness_weight: float = 0.5, normal_threshold: float = 60.0,
                  connectors: int = 3, connection_weights: str = "barycentric",
                  region_nodes: int = 6,
                  finger_stiffness: float | None = None, integrator="projective_dynamics",
                  substeps: int = 1, gravity=None,
                  skin_thickness: float = 0.002) -> "LatexPuppet":
        """Build a latex puppet from a closed mesh.

        mesh : path (OBJ, PLY, STL, GLB, ... anything trimesh loads) or trimesh.Trimesh [m]
        masses : target node count of the mass-spring mesh (all three layers)
        finger_regions : sidecar JSON path, dict {finger: vertex indices | spec}, or None
            (then <mesh>.json beside a mesh file if it exists, else chosen by position)
        materials : three presets (latex, foam, cavity): names from characters/materials.toml
            or Material objects, as a sequence or a dict {layer: preset}
        roundness_weight : decimation lambda; normal_threshold : tau [degrees]
        connectors : decimated vertices each visual vertex follows (connection map)
        connection_weights : "barycentric" (default: the closest decimated triangle among the
            nearest vertices by edge distance, smooth under rotation) or "distance" (equation 3's
            inverse edge distance weights; shows dimples around the nodes when the jaw turns)
        region_nodes : marked vertices per finger region that decimation must keep
        finger_stiffness : target spring [N/m] per region node; None = twice the median
            stiffness the region nodes already have from their springs
        integrator : "projective_dynamics" (default: the same backward Euler step as the
            paper's, solved by 6 local/global iterations on a prefactored matrix; measured 2-5x
            faster than "implicit_euler" for the same opening, see benchmarks/latex_puppet.py),
            "implicit_euler" (the paper's one Newton iteration, CG-solved), "verlet", or an
            Integrator; substeps : integrator substeps per step
        gravity : (3,) [m/s^2]; default none (the puppeteer's hand carries the head)
        skin_thickness : latex skin thickness [m] (the skin is the surface spring membrane)
        """
        timings: dict[str, float] = {}
        clock = time.perf_counter()
        _check_build_options(masses, connection_weights, region_nodes, skin_thickness)
        layer_materials = _resolve_materials(materials)
        integrator = _make_integrator(integrator, substeps)

        loaded = load_mesh(mesh)
        if finger_regions is None and isinstance(mesh, (str, Path)):
            sidecar = Path(mesh).with_suffix(".json")
            if sidecar.exists():
                finger_regions = sidecar
        clean = clean_surface(loaded.vertices, loaded.faces, colors=loaded.colors,
                              source=loaded.source)
        inside = InsideTest(clean.vertices, clean.faces)
        distance = SurfaceDistance(clean.vertices, clean.faces)
        timings["load"] = time.perf_counter() - clock

        surface_target = max(int(round(masses * _SURFACE_SHARE)), int(MIN_MASSES * 0.6))
        if surface_target > len(clean.vertices):
            raise ValueError(f"masses={masses} asks for about {surface_target} surface nodes but "
                             f"the mesh has only {len(clean.vertices)} vertices; use fewer "
                             f"masses or a finer mesh")
        spacing = target_edge_length(clean.vertices, clean.faces, surface_target)
        specs, landmarks = _region_specs(finger_regions, clean, spacing)
        members = resolve_regions(specs, clean.vertices, clean.faces, clean.index_map, distance)
        locked_sets = {name: idx[spread_subset(clean.vertices[idx], region_nodes)]
                       for name, idx in members.items()}
        locked = np.concatenate(list(locked_sets.values()))
        if len(locked) > surface_target // 2:
            raise ValueError(f"the finger regions keep {len(locked)} vertices through decimation "
                             f"but the decimated surface has room for about {surface_target}; "
                             f"ask for more masses or lower region_nodes")
        timings["regions"] = time.perf_counter() - clock - sum(timings.values())

        decimation, layers = _build_layers_to_count(
            clean, masses, surface_target, locked, roundness_weight=roundness_weight,
            normal_threshold=normal_threshold, inside=inside, distance=distance,
            timings=timings)
        kept = decimation.kept
        clock = time.perf_counter()

        regions = _decimated_regions(members, specs, clean, kept, layers)
        model, target_k, target_c = _make_model(layers, layer_materials, regions,
                                                finger_stiffness, gravity, skin_thickness)
        conn = _connection.build_connection(clean.vertices, clean.faces, kept,
                                            connectors=connectors, weighting=connection_weights,
                                            surface_faces=decimation.faces)
        timings["model"] = time.perf_counter() - clock

        report = _build_report(loaded.source, clean, decimation, layers, model, timings)
        log.info("latex puppet from %s: %s", loaded.source, report)
        return cls(model=model, layers=layers, surface_faces=decimation.faces,
                   surface_visual_index=kept, visual_vertices=clean.vertices, faces=clean.faces,
                   connection=conn, regions=regions, finger_stiffness=target_k,
                   finger_damping=target_c, landmarks=landmarks, vertex_colors=clean.colors,
                   integrator=integrator, materials=layer_materials, report=report)


def _check_build_options(masses, connection_weights, region_nodes, skin_thickness) -> None:
    if isinstance(masses, bool) or not isinstance(masses, (int, np.integer)):
        raise TypeError(f"masses must be an int (target node count), got {masses!r}")
    if masses < MIN_MASSES:
        raise ValueError(f"masses={masses} is too small for three closed layers: the latex "
                         f"skin needs a closed surface of at least ~{int(MIN_MASSES * 0.6)} "
                         f"vertices and the foam and cavity layers at least 4 nodes each "
                         f"beneath it; use masses >= {MIN_MASSES}")
    if connection_weights not in _connection.WEIGHTINGS:
        raise ValueError(f"connection_weights must be one of {_connection.WEIGHTINGS}, got "
                         f"{connection_weights!r}")
    if not isinstance(region_nodes, (int, np.integer)) or region_nodes < 1:
        raise ValueError(f"region_nodes must be an int >= 1, got {region_nodes!r}")
    if not (isinstance(skin_thickness, (int, float)) and skin_thickness > 0):
        raise ValueError(f"skin_thickness must be a length > 0 [m], got {skin_thickness!r}")


def _region_specs(finger_regions, clean: CleanSurface, spacing: float) -> tuple[dict, dict]:
    """({finger: RegionSpec}, {landmark: (L,) cleaned vertex indices}): the given regions (a
    sidecar or a dict, in the input mesh's vertex numbering) or ones chosen by position."""
    landmarks: dict[str, np.ndarray] = {}
    if finger_regions is None:
        return auto_regions(clean.vertices, 1.2 * spacing), landmarks
    specs, landmark_input = parse_regions(finger_regions)
    for name, index in landmark_input.items():
        bad = index[(index < 0) | (index >= len(clean.index_map))]
        if bad.size:
            raise ValueError(f"landmark {name!r}: vertex {int(bad[0])} does not exist")
        mapped = clean.index_map[index]
        landmarks[name] = mapped[mapped >= 0]
    return specs, landmarks


def _decimated_regions(members: dict, specs: dict, clean: CleanSurface, kept: np.ndarray,
                       layers: Layers) -> list[_Region]:
    """Each finger region on the decimated surface: every decimated vertex among its marked
    ones (at least its locked ones), its rest positions, its opening, its rows of the targets."""
    regions: list[_Region] = []
    position_of = np.full(len(clean.vertices), -1, dtype=np.int64)
    position_of[kept] = np.arange(len(kept))
    row = 0
    for name, idx in members.items():
        nodes = position_of[idx]
        nodes = np.sort(nodes[nodes >= 0])
        if nodes.size == 0:  # cannot happen while locked vertices survive; kept as a guard
            raise ValueError(f"finger region {name!r} was lost in decimation")
        spec = specs[name]
        opening = spec.opening or default_opening(clean.vertices, clean.faces, idx,
                                                  0.1 * float(np.ptp(clean.vertices, 0).max()))
        rest = layers.points[nodes]
        regions.append(_Region(name, nodes, rest, rest.mean(0), opening,
                               slice(row, row + len(nodes))))
        row += len(nodes)
    return regions


def _build_report(source, clean: CleanSurface, decimation: Decimation, layers: Layers,
                  model: MassSpring, timings: dict) -> BuildReport:
    r = roundness(layers.points, decimation.faces)
    volume = tetrahedron_volumes(layers.points, layers.tetrahedra).sum()
    return BuildReport(
        source=source, repairs=list(clean.repairs),
        visual_vertices=len(clean.vertices), visual_faces=len(clean.faces),
        surface_nodes=len(decimation.kept), layer_counts=tuple(int(c) for c in np.bincount(
            layers.layer, minlength=3)), tetrahedra=len(layers.tetrahedra),
        springs=model.spring_count, stopped_early=decimation.stopped_early,
        surface_roundness_mean=float(r.mean()), surface_roundness_min=float(r.min()),
        tetrahedra_volume_share=float(volume / signed_volume(clean.vertices, clean.faces)),
        seconds={k: round(v, 3) for k, v in timings.items()})


def _build_layers_to_count(clean: CleanSurface, masses: int, surface_target: int,
                           locked: np.ndarray, *, roundness_weight, normal_threshold, inside,
                           distance, timings) -> tuple[Decimation, Layers]:
    """Decimate and build layers, correcting the surface share once when the total node count
    misses `masses` by more than 10%."""
    best = None
    for _attempt in range(3):
        clock = time.perf_counter()
        decimation = decimate(clean.vertices, clean.faces, target_vertices=surface_target,
                              roundness_weight=roundness_weight,
                              normal_threshold=normal_threshold, locked=locked)
        timings["decimate"] = timings.get("decimate", 0.0) + time.perf_counter() - clock
        clock = time.perf_counter()
        layers = build_layers(clean.vertices[decimation.kept], decimation.faces, clean.vertices,
                              clean.faces, inside=inside, distance=distance)
        timings["layers"] = timings.get("layers", 0.0) + time.perf_counter() - clock
        total = len(layers.points)
        if best is None or abs(total - masses) < abs(len(best[1].points) - masses):
            best = (decimation, layers)
        miss = abs(total - masses) / masses
        if miss <= 0.1 or decimation.stopped_early:
            break
        new_target = int(round(surface_target * masses / total))
        new_target = min(max(new_target, len(locked) * 2, 8), len(clean.vertices))
        if new_target == surface_target:
            break
        log.debug("layers gave %d nodes for %d asked: surface target %d -> %d", total, masses,
                  surface_target, new_target)
        surface_target = new_target
    return best


def _make_model(layers: Layers, layer_materials, regions, finger_stiffness, gravity,
                skin_thickness):
    """MassSpring with per-layer springs and masses.

    Skin: the surface membrane of latex `skin_thickness` [m] thick; a triangular spring network
    has in-plane stiffness E t = 2 k / sqrt 3, so each skin spring gets k = (sqrt 3 / 2) E t, and
    each skin node a third of its triangles' area x t x density. Foam and cavity: springs of a
    tetrahedral lattice (k = E x rest length, the preset's damping ratio of critical), masses
    lumped from each tetrahedron's density x volume, a quarter per corner."""
    points = layers.points
    springs = layers.springs
    rest = np.linalg.norm(points[springs[:, 1]] - points[springs[:, 0]], axis=1)
    spacing = float(rest[layers.spring_layer == 0].mean())
    stiffness = np.zeros(len(springs))
    damping = np.zeros(len(springs))
    mass = np.zeros(len(points))
    skin, foam, cavity = layer_materials
    # skin membrane masses first: the damping of its springs depends on them
    a, b, c = (points[layers.surface_faces[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    np.add.at(mass, layers.surface_faces.ravel(),
              np.repeat(area * skin_thickness * skin.density / 3.0, 3))
    volume = np.abs(tetrahedron_volumes(points, layers.tetrahedra))
    density = np.where(layers.tetrahedron_layer == 2, cavity.density, foam.density)
    np.add.at(mass, layers.tetrahedra.ravel(), np.repeat(density * volume / 4.0, 4))
    mass = np.maximum(mass, 1e-6 * float(mass.max()))  # no weightless node
    on_skin = layers.spring_layer == 0
    stiffness[on_skin] = math.sqrt(3.0) / 2.0 * skin.youngs_modulus * skin_thickness
    pair_mass = np.minimum(mass[springs[:, 0]], mass[springs[:, 1]])
    damping[on_skin] = ((skin.damping_ratio or 0.0) * 2.0
                        * np.sqrt(stiffness[on_skin] * pair_mass[on_skin] / 2.0))
    for index, preset in ((1, foam), (2, cavity)):
        chosen = layers.spring_layer == index
        k, c, _ = preset.lattice_parameters(rest[chosen], spacing=spacing)
        stiffness[chosen] = k
        damping[chosen] = c
    rates = np.array([m.velocity_damping_rate() for m in layer_materials])
    layer_mass = np.bincount(layers.layer, weights=mass, minlength=3)
    velocity_damping = float(layer_mass @ rates / layer_mass.sum())
    model = MassSpring(points, springs, stiffness=stiffness, damping=damping, mass=mass,
                       velocity_damping=velocity_damping,
                       gravity=None if gravity is None else np.asarray(gravity, dtype=np.float64))
    target_nodes = np.concatenate([r.nodes for r in regions])
    if finger_stiffness is None:
        incident = np.bincount(springs[:, 0], stiffness, len(points)) + np.bincount(
            springs[:, 1], stiffness, len(points))
        finger_stiffness = 2.0 * float(np.median(incident[target_nodes]))
    finger_stiffness = float(finger_stiffness)
    if not finger_stiffness > 0 or not math.isfinite(finger_stiffness):
        raise ValueError(f"finger_stiffness must be a stiffness > 0 [N/m], got {finger_stiffness}")
    k_t = np.full(len(target_nodes), finger_stiffness)
    # critically damped pull of each node's own mass
    c_t = 2.0 * np.sqrt(k_t * mass[target_nodes])
    return model, k_t, c_t
