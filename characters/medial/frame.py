"""A medial object's frame in one compiled call: every Verlet substep poses the bones, adds the
spring and node forces, updates, and clamps to the circumspheres, with Python's lock released.

The same kernels, in the same order, as the integrator's substep loop (`Integrator._run` with
`Verlet._advance` and the constraint's `apply`), so both give identical states; the loop stays
for the spring-reduction constraint and for steps with pins, targets or forces.

    frame = FrameArrays.of(puppet)          # once; arrays shared with the puppet
    run_substeps(frame, x, v, substeps, h, retention)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..constraints import clamp_to_spheres
from ..kernels import node_forces, spring_forces_3d, spring_forces_elastic_3d, symplectic_update
from .joints import _section_transforms, carry_nodes, transform_by_section


class Pose(NamedTuple):
    """The joints and what they carry: section tree, the step's angles, the bones and the
    circumsphere centres (S sections, K kinematic nodes, D dynamic vertices)."""

    parent: np.ndarray              # (S,) int64, -1 for the root
    pivot: np.ndarray               # (S, 3) [mesh units]
    start: np.ndarray               # (S, 3) [rad] rotation vectors at the step's start
    goal: np.ndarray                # (S, 3) [rad] ... at its end
    now: np.ndarray                 # (S, 3) scratch: this substep's rotation vectors
    rotations: np.ndarray           # (S, 3, 3) scratch
    translations: np.ndarray        # (S, 3) scratch
    kinematic_rest: np.ndarray      # (K, 3)
    kinematic_section: np.ndarray   # (K,) int64
    kinematic_nodes: np.ndarray     # (K,) int64
    dynamic_rest: np.ndarray        # (D, 3)
    dynamic_section: np.ndarray     # (D,) int64
    centers: np.ndarray             # (D, 3) written: the circumsphere centres


class Body(NamedTuple):
    """The mass-spring model's arrays in the split kernels' layout, and the clamp."""

    si: np.ndarray                  # (M,) uint32 (model.plan)
    sj: np.ndarray
    rest_length: np.ndarray         # (M,) plan order
    stiffness: np.ndarray
    damping: np.ndarray
    damped: bool                    # any spring damper (else velocities are not gathered)
    scratch: np.ndarray             # (6, C) the plan's scratch
    mass: np.ndarray                # (N,)
    inverse_mass: np.ndarray        # (N,) 0 for kinematic nodes
    gravity: np.ndarray             # (3,)
    weighed: bool                   # gravity is not zero (else node forces add nothing)
    force: np.ndarray               # (N, 3) scratch
    sphere_nodes: np.ndarray        # (D,) int64
    sphere_radius: np.ndarray       # (D,)
    no_index: np.ndarray            # (0,) int64: no targets, no external forces
    no_rows: np.ndarray             # (0, 3)
    no_gains: np.ndarray            # (0,)


class FrameArrays(NamedTuple):
    pose: Pose
    body: Body

    @classmethod
    def of(cls, puppet, constraint) -> "FrameArrays":
        """Views of a MedialObject's arrays (the puppet writes its angles into them each step)
        and of its circumsphere `constraint`."""
        model = puppet.model
        plan = model.plan
        pose = Pose(np.ascontiguousarray(puppet.joints.parent, dtype=np.int64),
                    np.ascontiguousarray(puppet.joints.pivot, dtype=np.float64),
                    puppet._rotvec_start, puppet._rotvec_goal, puppet._rotvec_sub,
                    puppet._rotations, puppet._translations, puppet._kinematic_rest,
                    puppet._kinematic_section, puppet._kinematic_nodes, puppet._dynamic_rest,
                    puppet._dynamic_section, puppet._centers)
        body = Body(plan.si, plan.sj, plan.rest_length, plan.stiffness, plan.damping,
                    plan.damped, plan.scratch, model.mass, model.inverse_mass, model.gravity,
                    bool(model.gravity.any()),
                    np.zeros_like(model.rest_positions), constraint.nodes, constraint.radius,
                    np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
        return cls(pose, body)


@njit(cache=True, nogil=True)
def _pose_at(pose, fraction, inverse_h, x, v):
    """Bones and centres `fraction` of the way from the start angles to the goal."""
    for s in range(pose.now.shape[0]):
        for a in range(3):
            pose.now[s, a] = (pose.goal[s, a] - pose.start[s, a]) * fraction + pose.start[s, a]
    _section_transforms(pose.parent, pose.pivot, pose.now, pose.rotations, pose.translations)
    carry_nodes(pose.kinematic_rest, pose.kinematic_section, pose.kinematic_nodes,
                pose.rotations, pose.translations, x, v, inverse_h)
    transform_by_section(pose.dynamic_rest, pose.dynamic_section, pose.rotations,
                         pose.translations, pose.centers)


@njit(cache=True, nogil=True)
def _forces(body, x, v):
    """body.force := spring forces + gravity (velocity damping is Verlet's retention; no
    targets or external forces here)."""
    body.force[...] = 0.0
    if body.damped:
        spring_forces_3d(x, v, body.si, body.sj, body.rest_length, body.stiffness,
                         body.damping, body.scratch, body.force)
    else:
        spring_forces_elastic_3d(x, body.si, body.sj, body.rest_length, body.stiffness,
                                 body.scratch, body.force)
    if body.weighed:
        node_forces(x, v, body.mass, body.gravity, 0.0, body.no_index, body.no_rows,
                    body.no_gains, body.no_gains, body.no_index, body.no_rows, body.force)


@njit(cache=True, nogil=True)
def run_substeps(frame, x, v, substeps, h, retention):
    """`substeps` Verlet substeps of h [s] (velocity retention e^(-c_vd h) per substep)."""
    inverse_h = 1.0 / h
    for s in range(substeps):
        _pose_at(frame.pose, (s + 1) / substeps, inverse_h, x, v)
        _forces(frame.body, x, v)
        symplectic_update(x, v, frame.body.force, frame.body.inverse_mass, h, retention)
        clamp_to_spheres(x, v, frame.body.sphere_nodes, frame.pose.centers,
                         frame.body.sphere_radius, h)
