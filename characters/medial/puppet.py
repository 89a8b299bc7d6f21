"""Medial-surface elastic objects (Pfaff & Wuethrich 2007): a closed surface hung on its own
skeleton by bone springs, animated by rotating joint sections.

Build with :meth:`MedialObject.from_mesh`:

1. skeletonisation (``skeleton``): one skeletal point per surface vertex, from the
   Voronoi cells of the surface points, on the negative vertex normal;
2. mass-spring system: surface nodes and springs on the mesh edges; per vertex an inner bone
   point at ``p - f_bd (p - s)`` and an outer one at ``p + f_bd (p - s)`` (the reflection through
   the surface point), each joined to the surface node by a bone spring of rest length
   ``L = f_bd |p - s|``; bone points are kinematic (fixed nodes moved by the joints);
3. constraints on the bone springs, chosen per object: the circumsphere method (a node stays within
   ``(f_max - 1) L`` of its rest position, which moves with its bones) or spring reduction (both
   bone springs stay within ``[f_min, f_max] L``, iterated);
4. joints (``joints``): planes cut the skeleton into sections that form a binary
   tree; a section's angle rotates its bone points about the cut's pivot.

Node layout of ``model``: surface nodes ``0..V-1``, inner bone points ``V..2V-1``, outer bone
points ``2V..3V-1`` (node ``V + i`` and ``2V + i`` belong to surface vertex ``i``).
"""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from dataclasses import dataclass
from enum import Enum
from typing import Mapping

import numpy as np

from ..constraints import CircumsphereConstraint
from ..control import Control
from ..integrators import Verlet
from ..model import MassSpring
from . import joints as joint_kernels
from .constraints import BoneSpringReduction
from .frame import FrameArrays, run_substeps
from .joints import JointCut, JointSpec, JointTree
from .mesh_input import MAX_FACES, load_closed_mesh
from .skeleton import Skeleton, skeletonize

log = logging.getLogger(__name__)

__all__ = ["MedialObject", "ConstraintMethod", "MedialMaterial", "JointCut", "JointSpec",
           "TOO_COARSE_FALLBACK"]

#: more vertices than this fraction without an internal Voronoi point means the mesh is too
#: coarse for its curvature (the paper expects the fallback only at a few very sharp spots)
TOO_COARSE_FALLBACK = 0.25


class ConstraintMethod(str, Enum):
    """How the mass points are kept near their bones (paper section 3.2)."""

    CIRCUMSPHERE = "circumsphere"
    SPRING_REDUCTION = "spring_reduction"

    @classmethod
    def parse(cls, value) -> "ConstraintMethod":
        if isinstance(value, cls):
            return value
        try:
            return cls(value)
        except ValueError:
            raise ValueError(f"constraint must be one of {[m.value for m in cls]}, "
                             f"got {value!r}") from None


@dataclass(frozen=True)
class MedialMaterial:
    """The material parameters a medial object uses (paper section 3.3, Table 1).

    name : str
    bone_distance : float          f_bd / d_B in [0, 1]: bone points at this fraction of the way
                                   from the surface to the skeleton (0 = on the surface: rigid)
    max_factor : float             f_max / sl_max >= 1: the largest bone-spring length / rest length
    min_factor : float             f_min in (0, 1]: the smallest (spring reduction only)
    stiffness : float [1/s^2]      spring constant per unit node mass (k / m) of every spring
    velocity_damping : float [1/s] C_vd as a rate: velocities decay like exp(-rate t)
    """

    name: str
    bone_distance: float
    max_factor: float
    min_factor: float
    stiffness: float
    velocity_damping: float

    def __post_init__(self):
        checks = [
            ("bone_distance", 0.0 <= self.bone_distance <= 1.0, "in [0, 1]"),
            ("max_factor", self.max_factor >= 1.0, ">= 1"),
            ("min_factor", 0.0 < self.min_factor <= 1.0, "in (0, 1]"),
            ("stiffness", self.stiffness >= 0.0, ">= 0"),
            ("velocity_damping", self.velocity_damping >= 0.0, ">= 0"),
        ]
        for field, ok, expected in checks:
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and ok):
                raise ValueError(f"material {self.name!r}: {field} must be {expected}, "
                                 f"got {value!r}")

    @property
    def rigid(self) -> bool:
        """No elastic movement at all (Table 1's plastic: d_B = 0 or sl_max = 1)."""
        return self.bone_distance == 0.0 or self.max_factor == 1.0


def _as_medial_material(material) -> MedialMaterial:
    """A preset name, a core `Material`, a MedialMaterial or a mapping -> MedialMaterial."""
    if isinstance(material, MedialMaterial):
        return material
    if isinstance(material, Mapping):
        known = {"name", "bone_distance", "max_factor", "min_factor", "stiffness",
                 "velocity_damping"}
        unknown = set(material) - known
        if unknown:
            raise ValueError(f"material has unknown keys {sorted(unknown)}; expected "
                             f"{sorted(known)}")
        values = {"name": "custom", "min_factor": 0.8, **material}
        missing = known - set(values)
        if missing:
            raise ValueError(f"material is missing {sorted(missing)}")
        return MedialMaterial(**{k: (v if k == "name" else float(v)) for k, v in values.items()})
    from .. import materials as core_materials

    if isinstance(material, str):
        # the paper's names have spaces ("thick skin"); the preset table uses underscores
        name = material.strip().replace(" ", "_").replace("-", "_").lower()
        medial = core_materials.material_names("medial")
        if name not in medial:
            raise ValueError(f"unknown medial material {material!r}; known: "
                             f"{[m.replace('_', ' ') for m in medial]}")
        material = core_materials.material(name)
    if not isinstance(material, core_materials.Material):
        raise TypeError("material must be a preset name, a characters.materials.Material, a "
                        f"MedialMaterial or a dict, got {type(material).__name__}")
    return _from_core_material(material)


def _from_core_material(material) -> MedialMaterial:
    """Map a preset of characters/materials.toml to a medial object's parameters.

    Keys that do not apply ("var" in the paper's Table 1, e.g. plastic's D and C_vd) become 0;
    a missing bone_distance or max_stretch means the preset is not for medial objects.
    """
    if material.bone_distance is None or material.max_stretch is None:
        raise ValueError(f"material {material.name!r} (family {material.family!r}) has no "
                         "bone_distance / max_stretch: not a medial-object material; use one of "
                         "the medial presets or give those keys")
    return MedialMaterial(
        name=material.name,
        bone_distance=float(material.bone_distance),
        max_factor=float(material.max_stretch),
        min_factor=float(material.min_stretch if material.min_stretch is not None else 0.8),
        stiffness=float(material.stiffness or 0.0),
        velocity_damping=material.velocity_damping_rate())


class MedialObject:
    """An elastic object on its medial skeleton; one of the three puppet kinds.

    Attributes (all rest-state arrays read-only):
    mesh : trimesh.Trimesh            the repaired input surface
    faces : (F, 3) int                its triangles (constant)
    rest_vertices : (V, 3) float [mesh units]
    skeleton : (V, 3) float [mesh units]   one skeletal point per surface vertex, same connectivity
    skeleton_info : Skeleton           depth, fallback and clamp flags of the skeletonisation
    bone_rest_length : (V,) float [mesh units]   L = f_bd x skeleton depth per vertex
    material : MedialMaterial; constraint : ConstraintMethod
    joints : JointTree                 sections (index 0 = the whole object)
    model : MassSpring; state : SpringState   nodes: surface 0..V-1, inner bones V..2V-1,
                                       outer bones 2V..3V-1
    dynamic_vertices : (D,) int        surface vertices simulated (bone length > 0)
    kinematic_vertices : (V - D,) int  surface vertices carried rigidly with their section
    bone_spring_index : (2D,) int      indices of the bone springs in model.springs
    max_substep : float [s]            the largest stable Verlet substep
    target_names : tuple[str, ...]     the joint sections `step` accepts angles for
    """

    def __init__(self, *, mesh, skeleton: Skeleton, material: MedialMaterial,
                 constraint: ConstraintMethod, joints: JointTree, mass: float,
                 iterations: int, substeps: int | None):
        self.mesh = mesh
        self.faces = np.asarray(mesh.faces, dtype=np.int64)
        self.faces.setflags(write=False)
        rest = np.array(mesh.vertices, dtype=np.float64)
        vertex_count = len(rest)
        self.rest_vertices = rest
        self.skeleton_info = skeleton
        self.skeleton = skeleton.points
        self.material = material
        self.constraint = constraint
        self.joints = joints
        self.vertex_count = vertex_count

        fbd = material.bone_distance
        offset = rest - skeleton.points                       # (V, 3) surface minus skeleton
        self.bone_rest_length = fbd * skeleton.depth
        inner = rest - fbd * offset
        outer = rest + fbd * offset
        # a vertex whose bone springs have no length (rigid material, or no internal Voronoi
        # point) cannot move relative to its bones: it is kinematic, carried like a bone point
        dynamic = (self.bone_rest_length > 0.0) & (not material.rigid)
        self.dynamic_vertices = np.flatnonzero(dynamic)
        self.kinematic_vertices = np.flatnonzero(~dynamic)

        edges = np.asarray(mesh.edges_unique, dtype=np.int64)
        dyn = self.dynamic_vertices
        bone_springs = np.concatenate([np.stack([dyn, vertex_count + dyn], axis=1),
                                       np.stack([dyn, 2 * vertex_count + dyn], axis=1)])
        springs = np.concatenate([edges, bone_springs])
        rest_length = np.concatenate([np.asarray(mesh.edges_unique_length),
                                      self.bone_rest_length[dyn], self.bone_rest_length[dyn]])
        self.surface_spring_count = len(edges)
        self.bone_spring_index = np.arange(len(edges), len(springs))
        positions = np.concatenate([rest, inner, outer])
        fixed = np.ones(3 * vertex_count, dtype=bool)
        fixed[dyn] = False
        node_mass = float(mass) / vertex_count
        stiffness = material.stiffness * node_mass

        constraints = _bone_constraints(constraint, material, dyn, vertex_count,
                                        self.bone_rest_length[dyn], iterations)
        self.model = MassSpring(positions, springs, stiffness=stiffness, mass=node_mass,
                                velocity_damping=material.velocity_damping,
                                rest_length=rest_length, fixed=fixed, constraints=constraints)
        self.state = self.model.state()

        self.max_substep = _stable_substep(self.model, dyn, node_mass)   # [s]
        self.fixed_substeps = substeps

        self._prepare_joints(positions, rest, fixed, dyn, constraints)
        self.integrator = _PosedVerlet(self, check_energy=False)
        for array in (self.rest_vertices, self.skeleton, self.bone_rest_length,
                      self.dynamic_vertices, self.kinematic_vertices):
            array.setflags(write=False)

    def _prepare_joints(self, positions, rest, fixed, dyn, constraints) -> None:
        """The rest arrays the joints transform each step, and the per-section buffers."""
        joints = self.joints
        section_of_node = np.concatenate([joints.section_of_vertex] * 3).astype(np.int64)
        self._kinematic_nodes = np.flatnonzero(fixed)
        self._kinematic_rest = np.ascontiguousarray(positions[self._kinematic_nodes])
        self._kinematic_section = np.ascontiguousarray(section_of_node[self._kinematic_nodes])
        self._dynamic_rest = np.ascontiguousarray(rest[dyn])
        self._dynamic_section = np.ascontiguousarray(joints.section_of_vertex[dyn])
        self._centers = self._dynamic_rest.copy()  # posed each substep; finite from the start
        section_count = len(joints.names)
        self._rotvec = np.zeros((section_count, 3))
        self._rotvec_start = np.zeros((section_count, 3))
        self._rotvec_sub = np.zeros((section_count, 3))
        self._rotvec_goal = np.zeros((section_count, 3))
        self._rotations = np.repeat(np.eye(3)[None], section_count, axis=0)
        self._translations = np.zeros((section_count, 3))
        centers = {c.name: self._centers for c in constraints
                   if isinstance(c, CircumsphereConstraint)}
        self._control = Control(constraint_centers=centers)

    # construction ----------------------------------------------------------------------------
    @classmethod
    def from_mesh(cls, mesh, *, material="skin", constraint="circumsphere", joints=None,
                  f_min: float | None = None, f_max: float | None = None, mass: float = 1.0,
                  iterations: int = 8, substeps: int | None = None,
                  check_self_intersections: bool = True,
                  max_faces: int = MAX_FACES) -> "MedialObject":
        """Build a medial object from a closed surface.

        mesh : path or trimesh.Trimesh     closed, consistently wound surface (see mesh_input for
                                           the repairs made and the errors raised)
        material : str | MedialMaterial | dict   a preset name ("thick skin", "water", "plastic",
                                           "skin", "tight cloth") or explicit parameters
        constraint : "circumsphere" | "spring_reduction"
        joints : None | path to a joints JSON | JointSpec | list of JointCut or dicts
        f_min, f_max : float | None        override the material's bone-spring length limits
                                           (f_min in (0, 1], f_max >= 1)
        mass : float [kg]                  total mass of the surface nodes
        iterations : int                   spring-reduction passes per substep
        substeps : int | None              Verlet substeps per step; None = as many as the
                                           material's stiffness needs for stability
        max_faces : int                    refuse larger meshes (the Voronoi step takes minutes
                                           beyond it); raise it to build one anyway
        """
        constraint = ConstraintMethod.parse(constraint)
        medial_material = _as_medial_material(material)
        if f_min is not None or f_max is not None:
            medial_material = dataclasses.replace(
                medial_material,
                min_factor=medial_material.min_factor if f_min is None else f_min,
                max_factor=medial_material.max_factor if f_max is None else f_max)
        if not (isinstance(mass, (int, float)) and math.isfinite(mass) and mass > 0):
            raise ValueError(f"mass must be a positive number [kg], got {mass!r}")
        if not isinstance(iterations, (int, np.integer)) or iterations < 1:
            raise ValueError(f"iterations must be an int >= 1, got {iterations!r}")
        if substeps is not None and (not isinstance(substeps, (int, np.integer)) or substeps < 1):
            raise ValueError(f"substeps must be None or an int >= 1, got {substeps!r}")
        spec = JointSpec.coerce(joints)
        surface = load_closed_mesh(mesh, check_self_intersections=check_self_intersections,
                                   max_faces=max_faces)
        skeleton = skeletonize(surface)
        fallback = float(skeleton.fallback.mean())
        if fallback > TOO_COARSE_FALLBACK:
            raise ValueError(
                f"the mesh is too coarse for its curvature: {fallback:.0%} of its "
                f"{len(surface.vertices)} vertices have no internal Voronoi point (at most "
                f"{TOO_COARSE_FALLBACK:.0%} expected); subdivide it (trimesh.remesh.subdivide)")
        if skeleton.fallback.any():
            log.info("%d of %d vertices had no internal Voronoi point: their skeletal point is "
                     "the vertex itself", int(skeleton.fallback.sum()), len(surface.vertices))
        tree = joint_kernels.build_joint_tree(
            spec, skeleton.points, edge_length=float(surface.edges_unique_length.mean()))
        return cls(mesh=surface, skeleton=skeleton, material=medial_material,
                   constraint=constraint, joints=tree, mass=float(mass), iterations=int(iterations),
                   substeps=substeps)

    @classmethod
    def shipped(cls, name: str = "medial_caterpillar", **options) -> "MedialObject":
        """A creature shipped in characters/assets/: NAME.obj with its NAME.joints.json.

        options : passed to :meth:`from_mesh` (material, constraint, ...).
        """
        folder = Path(__file__).resolve().parent.parent / "assets"
        mesh = folder / f"{name}.obj"
        joints = folder / f"{name}.joints.json"
        if not mesh.exists() or not joints.exists():
            shipped = sorted(p.name[:-len(".joints.json")] for p in folder.glob("*.joints.json"))
            raise ValueError(f"no shipped medial object {name!r} in {folder}; shipped: {shipped}")
        options.setdefault("joints", joints)
        return cls.from_mesh(mesh, **options)

    # the puppet interface -----------------------------------------------------------------------
    @property
    def target_names(self) -> tuple[str, ...]:
        return self.joints.joint_names

    def reset(self) -> None:
        """Back to rest: every section at angle 0, nodes at rest, zero velocity."""
        self.state.assign(self.model.state())
        self._rotvec[...] = 0.0

    def surface(self) -> np.ndarray:
        """(V, 3) float [mesh units]: the deformed surface now (a copy)."""
        return self.state.x[:self.vertex_count].copy()

    def substeps_for(self, dt: float) -> int:
        """Verlet substeps used for a step of dt [s]."""
        if self.fixed_substeps is not None:
            return self.fixed_substeps
        return max(1, math.ceil(dt / self.max_substep)) if math.isfinite(self.max_substep) else 1

    def rotation_vectors(self, targets: Mapping | None) -> np.ndarray:
        """(S, 3) float [rad]: each section's rotation vector for these targets (0 if absent)."""
        out = np.zeros_like(self._rotvec)
        if targets is None:
            return out
        if not isinstance(targets, Mapping):
            raise TypeError(f"targets must be a mapping {{section name: angle}}, got "
                            f"{type(targets).__name__}")
        names = self.joints.names
        for name, value in targets.items():
            if name not in self.target_names:
                raise ValueError(f"unknown target {name!r}; this medial object's targets are "
                                 f"{list(self.target_names)}")
            index = names.index(name)
            angle = np.asarray(value, dtype=np.float64).ravel()
            if not np.all(np.isfinite(angle)):
                raise ValueError(f"target {name!r}: angle must be finite, got {value!r}")
            if angle.size == 1:
                out[index] = float(angle[0]) * self.joints.axis[index]
            elif angle.size == 3:
                out[index] = angle
            else:
                raise ValueError(f"target {name!r}: expected an angle [rad] (scalar) or a rotation "
                                 f"vector (3,), got {angle.size} values")
        return out

    def step(self, dt: float, targets: Mapping | None = None) -> None:
        """Advance by dt [s] with section angles `targets` {section: angle [rad] | (3,)}.

        Absent sections return to angle 0. Within the step the angles move linearly from the
        previous step's, so the bones sweep rather than jump.
        """
        dt = float(dt)
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a finite time step > 0 [s], got {dt}")
        goal = self.rotation_vectors(targets)
        self._rotvec_start[...] = self._rotvec
        self._rotvec_goal[...] = goal
        # one integrator step of `substeps` substeps; each first poses the bones (_PosedVerlet)
        self.integrator.substeps = self.substeps_for(dt)
        self.integrator.step(self.model, self.state, dt, self._control)
        self._rotvec[...] = goal

    # internals ------------------------------------------------------------------------------------
    def _pose_at(self, fraction: float, h: float) -> None:
        """Pose the bones `fraction` of the way from the step's start angles to its goal."""
        np.subtract(self._rotvec_goal, self._rotvec_start, out=self._rotvec_sub)
        self._rotvec_sub *= fraction
        self._rotvec_sub += self._rotvec_start
        self._pose_bones(self._rotvec_sub, h)

    def _pose_bones(self, rotation_vectors, h: float) -> None:
        """Move kinematic nodes and constraint centres to the pose; bone velocities = motion / h."""
        joint_kernels.section_transforms(self.joints, rotation_vectors, self._rotations,
                                         self._translations)
        joint_kernels.carry_nodes(self._kinematic_rest, self._kinematic_section,
                                  self._kinematic_nodes, self._rotations, self._translations,
                                  self.state.x, self.state.v, 1.0 / h)
        joint_kernels.transform_by_section(self._dynamic_rest, self._dynamic_section,
                                           self._rotations, self._translations, self._centers)

    def posed_rest(self, targets: Mapping | None = None) -> np.ndarray:
        """(V, 3) float: where each surface vertex would rest with these section angles."""
        rotations = np.empty_like(self._rotations)
        translations = np.empty_like(self._translations)
        joint_kernels.section_transforms(self.joints, self.rotation_vectors(targets), rotations,
                                         translations)
        out = np.empty_like(self.rest_vertices)
        joint_kernels.transform_by_section(self.rest_vertices, self.joints.section_of_vertex,
                                           rotations, translations, out)
        return out

    def __repr__(self) -> str:
        return (f"MedialObject({self.vertex_count} vertices, {self.model.spring_count} springs, "
                f"material={self.material.name!r}, constraint={self.constraint.value!r}, "
                f"sections={list(self.joints.names)})")


class _PosedVerlet(Verlet):
    """Verlet stepping a medial object: each substep first carries its bones to the pose that
    substep ends at, so one integrator step covers a whole frame (one set of checks per frame,
    not per substep). With the circumsphere constraint the substeps run in one compiled call
    (`frame.run_substeps`, the same kernels in the same order, Python's lock released)."""

    def __init__(self, puppet: MedialObject, **options):
        super().__init__(**options)
        self._pose = puppet._pose_at
        spheres = [c for c in puppet.model.constraints if isinstance(c, CircumsphereConstraint)]
        compiled = len(spheres) == len(puppet.model.constraints) == 1
        self._frame = FrameArrays.of(puppet, spheres[0]) if compiled else None

    def _begin_substep(self, state, fraction: float, h: float) -> None:
        self._pose(fraction, h)

    def _run(self, model, state, dt, control, substeps, scratch) -> int:
        plain = (control.pin_index.size or control.target_index.size
                 or control.force_index.size)
        if self._frame is None or plain or self._frame.body.mass is not model.mass:
            return super()._run(model, state, dt, control, substeps, scratch)
        h = dt / substeps
        run_substeps(self._frame, state.x, state.v, substeps, h,
                     math.exp(-model.velocity_damping * h))
        return 0


def _bone_constraints(constraint, material, dyn, vertex_count, bone_rest, iterations) -> list:
    """The medial constraint on the dynamic vertices' bone springs (none when nothing moves)."""
    if not len(dyn):
        return []
    if constraint is ConstraintMethod.CIRCUMSPHERE:
        # radius (f_max - 1) L: see docs/medial_objects.md for why not f_max L
        radius = (material.max_factor - 1.0) * bone_rest
        return [CircumsphereConstraint(dyn, radius=radius, name="medial_sphere")]
    # the core's SpringReductionConstraint on the bone springs, computed per mass point with an
    # early stop (same results, tested; see medial/constraints)
    return [BoneSpringReduction(dyn, vertex_count + dyn, 2 * vertex_count + dyn, bone_rest,
                                min_factor=material.min_factor, max_factor=material.max_factor,
                                iterations=iterations)]


def _stable_substep(model, dyn, node_mass: float) -> float:
    """The largest stable Verlet substep [s], with a 0.8 margin: h < 2 / omega_max, where
    omega_max^2 <= 2 max_i sum_j k_ij / m_i over the dynamic vertices."""
    incident = np.zeros(model.node_count)
    np.add.at(incident, model.springs[:, 0], model.stiffness)
    np.add.at(incident, model.springs[:, 1], model.stiffness)
    omega_max = math.sqrt(2.0 * float(incident[dyn].max(initial=0.0)) / node_mass)
    return 0.8 * 2.0 / omega_max if omega_max > 0 else math.inf
