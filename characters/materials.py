"""Material presets as data: characters/materials.toml parsed once into frozen dataclasses.

    from characters import material, material_names
    skin = material("skin")                  # Material(name="skin", family="medial", ...)
    model = MassSpring(x, springs, stiffness=skin.stiffness * node_mass,
                       velocity_damping=skin.velocity_damping_rate(), ...)
    k, c, m = material("latex_skin").lattice_parameters(rest_length, spacing=...)

A user TOML file with the same layout can add presets or override keys of existing ones:
`load_materials(path)` returns the merged table (defaults + overlay) without touching the
built-in one; errors name the file and the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

DEFAULTS = Path(__file__).with_name("materials.toml")
FAMILIES = ("medial", "animatron", "latex")
#: C_vd in the TOML is the fraction of velocity kept per frame at this rate [1/s]
REFERENCE_FRAME_RATE = 25.0


@dataclass(frozen=True)
class Material:
    """One preset. None = the key does not apply to this material (see materials.toml)."""

    name: str
    family: str
    description: str = ""
    source: str = ""
    stiffness: float | None = None          # k / m [1/s^2]
    damping: float | None = None            # c / m [1/s]
    velocity_damping: float | None = None   # C_vd: velocity fraction kept per 1/25 s
    bone_distance: float | None = None      # d_B
    max_stretch: float | None = None        # sl_max = f_max
    min_stretch: float | None = None        # f_min
    youngs_modulus: float | None = None     # [Pa]
    density: float | None = None            # [kg/m^3]
    damping_ratio: float | None = None      # fraction of critical, per spring

    def velocity_damping_rate(self) -> float:
        """C_vd as the rate MassSpring takes [1/s]: -ln(C_vd) x 25 (0 if not given)."""
        if self.velocity_damping is None:
            return 0.0
        return -math.log(self.velocity_damping) * REFERENCE_FRAME_RATE

    def spring_parameters(self, node_mass) -> tuple[np.ndarray, np.ndarray]:
        """(stiffness [N/m], damping [N s/m]) for springs between nodes of node_mass [kg]."""
        if self.stiffness is None:
            raise ValueError(f"material {self.name!r} has no per-mass stiffness (family "
                             f"{self.family!r}); use lattice_parameters for volumetric meshes")
        m = np.asarray(node_mass, dtype=np.float64)
        return self.stiffness * m, (self.damping or 0.0) * m

    def lattice_parameters(self, rest_length, *, spacing: float):
        """(stiffness (M,) [N/m], damping (M,) [N s/m], node mass [kg]) for a tetrahedral mesh.

        Springs of a cubic-ish lattice with edge `spacing` [m]: k = E x rest length, node
        mass = density x spacing^3, damping = damping_ratio x critical (2 sqrt(k m / 2)).
        """
        if self.youngs_modulus is None or self.density is None:
            raise ValueError(f"material {self.name!r} has no youngs_modulus/density (family "
                             f"{self.family!r}); use spring_parameters")
        if not spacing > 0:
            raise ValueError(f"spacing must be > 0 [m], got {spacing}")
        rest = np.asarray(rest_length, dtype=np.float64)
        k = self.youngs_modulus * rest
        node_mass = self.density * spacing ** 3
        c = (self.damping_ratio or 0.0) * 2.0 * np.sqrt(k * node_mass / 2.0)
        return k, c, node_mass


_FLOAT_KEYS = {f.name for f in fields(Material)} - {"name", "family", "description", "source"}


def _parse(table: Mapping, source: str, base: Mapping[str, Material] | None = None):
    out = dict(base or {})
    for name, entry in table.items():
        if not isinstance(entry, Mapping):
            raise ValueError(f"{source}: [{name}] must be a table of keys, got {entry!r:.60}")
        unknown = set(entry) - {f.name for f in fields(Material)}
        if unknown:
            raise ValueError(f"{source}: [{name}] has unknown key(s) {sorted(unknown)}; known: "
                             f"{sorted(f.name for f in fields(Material) if f.name != 'name')}")
        values = {}
        for key, value in entry.items():
            if key in _FLOAT_KEYS:
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ValueError(f"{source}: [{name}] {key} must be a number, got {value!r}")
                value = float(value)
                if not math.isfinite(value) or value < 0:
                    raise ValueError(f"{source}: [{name}] {key} must be finite and >= 0, got "
                                     f"{value}")
            elif not isinstance(value, str):
                raise ValueError(f"{source}: [{name}] {key} must be a string, got {value!r}")
            values[key] = value
        if "velocity_damping" in values and not 0 < values["velocity_damping"] <= 1:
            raise ValueError(f"{source}: [{name}] velocity_damping (C_vd, velocity kept per "
                             f"frame) must be in (0, 1], got {values['velocity_damping']}")
        if "max_stretch" in values and values["max_stretch"] < 1:
            raise ValueError(f"{source}: [{name}] max_stretch must be >= 1, got "
                             f"{values['max_stretch']}")
        if "min_stretch" in values and not 0 < values["min_stretch"] <= 1:
            raise ValueError(f"{source}: [{name}] min_stretch must be in (0, 1], got "
                             f"{values['min_stretch']}")
        if name in out:
            out[name] = replace(out[name], **values)
        else:
            family = values.pop("family", None)
            if family not in FAMILIES:
                raise ValueError(f"{source}: [{name}] family must be one of {FAMILIES}, got "
                                 f"{family!r}")
            out[name] = Material(name=name, family=family, **values)
        if out[name].family not in FAMILIES:
            raise ValueError(f"{source}: [{name}] family must be one of {FAMILIES}, got "
                             f"{out[name].family!r}")
    return MappingProxyType(out)


def _read(path: Path) -> dict:
    from characters.sidecar import read_toml
    return read_toml(path, "materials file")


@lru_cache(maxsize=1)
def _defaults() -> Mapping[str, Material]:
    return _parse(_read(DEFAULTS), str(DEFAULTS))


def load_materials(path) -> Mapping[str, Material]:
    """The built-in presets overlaid with a user TOML file (new names added, keys overridden)."""
    path = Path(path)
    return _parse(_read(path), str(path), _defaults())


def material_names(family: str | None = None) -> list[str]:
    """Names of the built-in presets, optionally of one family ("medial", "animatron", "latex")."""
    if family is not None and family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES} or None, got {family!r}")
    return [name for name, m in _defaults().items() if family is None or m.family == family]


def material(name: str) -> Material:
    """A built-in preset by name."""
    table = _defaults()
    if isinstance(name, Material):
        return name
    try:
        return table[name]
    except KeyError:
        raise ValueError(f"unknown material {name!r}; known: {sorted(table)}") from None
