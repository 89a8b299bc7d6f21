"""Elastic characters: the mass-spring core, integrators, constraints, materials, motion clips
and the three puppet kinds (image, latex, medial).

Names are resolved lazily so that importing one puppet kind never pulls in the heavy
dependencies of another (trimesh, OpenCV)."""
import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    # core (model / state / control)
    "model": ["MassSpring", "SpringState", "tetrahedral_lattice"],
    "control": ["Control"],
    # integrators
    "integrators": ["ImplicitEuler", "Verlet", "ProjectiveDynamics", "StepReport", "Integrator",
                    "StepFailure", "default_integrator"],
    # constraints and materials
    "constraints": ["CircumsphereConstraint", "SpringReductionConstraint"],
    "materials": ["Material", "material", "material_names", "load_materials"],
    # motion clips
    "motion": ["Motion", "blend", "Interpolation"],
    # the shape every puppet kind shares, and the kinds (one package each)
    "puppet": ["Puppet"],
    "image.puppet": ["ImagePuppet"],
    "latex.puppet": ["LatexPuppet"],
    "medial.puppet": ["MedialObject"],
})
