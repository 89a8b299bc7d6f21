"""Elastic characters: the mass-spring core, integrators, constraints, materials, motion clips
and the three puppet kinds (image, latex, medial).

Names are resolved lazily so that importing one puppet kind never pulls in the heavy
dependencies of another (trimesh, OpenCV, pyrender)."""
from importlib import import_module

_EXPORTS = {
    # core (model / state / control)
    "MassSpring": "characters.model",
    "SpringState": "characters.model",
    "Control": "characters.control",
    # integrators
    "ImplicitEuler": "characters.integrators",
    "Verlet": "characters.integrators",
    "ProjectiveDynamics": "characters.integrators",
    "StepReport": "characters.integrators",
    "Integrator": "characters.integrators",
    "StepFailure": "characters.integrators",
    "default_integrator": "characters.integrators",
    # constraints and materials
    "CircumsphereConstraint": "characters.constraints",
    "SpringReductionConstraint": "characters.constraints",
    "Material": "characters.materials",
    "material": "characters.materials",
    "material_names": "characters.materials",
    "load_materials": "characters.materials",
    "tetrahedral_lattice": "characters.model",
    # motion clips
    "Motion": "characters.motion",
    "blend": "characters.motion",
    "Interpolation": "characters.motion",
    # puppet kinds
    "ImagePuppet": "characters.image.puppet",
    "LatexPuppet": "characters.latex.puppet",
    "MedialObject": "characters.medial.puppet",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'characters' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value
