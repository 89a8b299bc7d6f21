"""Image puppets: any picture of a character becomes an elastic 2D puppet (Animatron's puppet
tool, plus an as-rigid-as-possible mode and keyframe baking).

    from characters import ImagePuppet, Motion
    puppet = ImagePuppet.from_image("monster.png")          # path or (H, W[, C]) array
    puppet.add_pin((120, 300), name="hand")                  # driven by motions
    puppet.add_pin((250, 480), name="feet", fixed=True)      # an anchor
    for t in frame_times:
        puppet.step(1 / 25, motion.sample(t))                 # {pin name: (2,) position [px]}
        draw(puppet.image, puppet.vertices, puppet.surface(), puppet.triangles)

Building (`from_image`): background removal (characters/image/background.py), largest
component, contour, regular grid kept by the even-odd rule plus border cells, two triangles and
six springs per cell, equal masses (characters/image/mesh.py).

Pins hold a small patch (the vertex and its grid neighbours) rather than one vertex, so a
pulled pin drags a piece of the picture instead of drawing a spike.

Two ways to move the mesh:
- mode "springs" (default): the mass-spring network with Verlet integration and damping; the
  material (liquid, fabric, rubber, rigid: characters/materials.toml) sets stiffness and
  damping, scaled with the grid so the cell size does not change the look. A no-fold constraint
  (characters/image/guard.py) keeps triangles from turning inside out when the sheet is
  pushed together (springs alone have no sense of area). The picture has
  inertia: it lags behind, overshoots and wobbles, and keeps moving after the pins stop. The
  shape depends on the history, so frames must be simulated in order (or baked).
- mode "arap": as-rigid-as-possible shape manipulation (Igarashi et al. 2005, characters/image/
  arap.py): the shape is a function of the current pin positions only, with no dynamics and no
  material; local shape is preserved as well as possible (parts bend and rotate rather than
  stretch). Any frame can be computed directly, at the cost of one sparse factorisation when
  the set of active pins changes. It needs two pins to deform (one pin only translates).
Choose springs for lively, physical secondary motion (jiggle, follow-through, floppy
characters); choose arap for controlled posing that keeps the drawing's proportions, for
scrubbing / random access in time, and when pins jump (springs would ring).

Coordinates: picture pixels, pixel centres at integer (x = column, y = row), y down.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import Enum
from typing import Mapping

import numpy as np

from ..control import Control
from ..integrators import Verlet
from ..materials import Material, material_names
from ..materials import material as lookup_material
from ..model import MassSpring
from .arap import ArapDeformer
from .background import load_image, remove_background, require_cv2, shrink_any
from .bake import BakedMotion, bake_motion
from .frame import FrameArrays, run_substeps
from .guard import NoFoldConstraint
from .mesh import GridMesh, build_grid_mesh, signed_areas
from .skeleton import ProposedPin, propose_pins

log = logging.getLogger(__name__)

DEFAULT_CELLS_ACROSS = 24     # grid cells along the character's longer side, by default
DEFAULT_PIN_RADIUS = 1.5      # [cells] a pin holds the vertices this close to its own
DEFAULT_MAX_MESH_SIZE = 1024  # [px] longer side above which the mesh is built on a downscaled copy


class PuppetMode(str, Enum):
    SPRINGS = "springs"
    ARAP = "arap"


REFERENCE_CELLS_ACROSS = DEFAULT_CELLS_ACROSS   # presets hold as given on this grid


def image_material(material) -> Material:
    """A preset name (characters/materials.toml) or a `Material` with a per-mass stiffness."""
    if isinstance(material, str):
        key = material.strip().lower()
        usable = [name for name in material_names()
                  if lookup_material(name).stiffness is not None]
        if key not in material_names():
            others = [name for name in usable if name not in material_names("animatron")]
            raise ValueError(f"unknown material {material!r} for an image puppet; choose one of "
                             f"{material_names('animatron')} (other presets with a spring "
                             f"stiffness work too: {others})")
        material = lookup_material(key)
    if not isinstance(material, Material):
        raise TypeError(f"material must be a preset name or a characters.Material, got "
                        f"{type(material).__name__}")
    if material.stiffness is None:
        raise ValueError(f"material {material.name!r} ({material.family}) has no per-mass spring "
                         f"stiffness, so it cannot drive an image puppet; choose one of "
                         f"{material_names('animatron')}")
    return material


def spring_parameters(material: Material, cells_across: float) -> tuple[float, float, float]:
    """(stiffness k / m [1/s^2], along-spring damping c / m [1/s], velocity damping rate
    [1/s]) for a grid `cells_across` cells wide.

    A grid with n cells across behaves like a continuum whose stiffness and viscosity fall as
    1 / n^2 per spring; scaling k and c by (n / 24)^2 keeps a character's look the same
    whatever the cell size, and gives the preset's own numbers on the default 24-cell grid."""
    scale = (cells_across / REFERENCE_CELLS_ACROSS) ** 2
    return (material.stiffness * scale, (material.damping or 0.0) * scale,
            material.velocity_damping_rate())


@dataclass(frozen=True)
class Pin:
    """A named mesh vertex: index into vertices, the point asked for (x, y) [px], whether it
    is an anchor (held at rest) or driven by `step` targets, and the patch it holds: region
    (P,) int vertices (the pin's vertex first) moved together by the pin's displacement."""

    name: str
    index: int
    requested: tuple[float, float]
    fixed: bool
    region: tuple[int, ...]


class ImagePuppet:
    """A picture on an elastic triangle mesh, driven by named pins.

    Build with `from_image`. Attributes (read-only arrays):

    image : (H, W, 4) uint8 RGBA: the picture with the character's alpha (straight alpha)
    mask : (H, W) bool: what was kept as the character
    vertices : (N, 2) float [px]: rest mesh; triangles : (F, 3) int (positive signed area);
    faces : the same triangles; springs : (M, 2) int; uv : (N, 2) float in [0, 1]: texture
    coordinates (u = (x + 0.5) / W, v = (y + 0.5) / H, v pointing down the picture)
    contour : (K, 2) float [px]: the character's outer contour
    kind : str: how the character was found ("alpha", "plain", "photo", "drawing", or
    "given" for a mask handed in); notes : tuple of str: what the cut-out wants a user to know
    cell_size : float [px]; mesh_scale : float: meshed resolution / picture resolution (< 1 for
    large pictures, which are meshed on a downscaled copy and rendered at full size)
    model : MassSpring, state : SpringState; mode : PuppetMode; material : Material
    pins : {name: Pin}; target_names : names `step` accepts (the driven pins)
    """

    def __init__(self, *, image: np.ndarray, mask: np.ndarray, mesh: GridMesh,
                 mesh_scale: float, material="rubber", mode="springs", kind: str = "given",
                 notes: tuple = ()):
        try:
            self.mode = PuppetMode(mode)
        except ValueError:
            raise ValueError(f"mode must be one of {[m.value for m in PuppetMode]}, got "
                             f"{mode!r}") from None
        self.material = image_material(material)
        self.image = image
        self.mask = mask
        self.kind = str(kind)
        self.notes = tuple(notes)
        self.mesh_scale = float(mesh_scale)
        self._mesh = mesh
        to_full = self._to_picture
        self.vertices = to_full(mesh.vertices)
        self.triangles = mesh.triangles
        self.springs = mesh.springs
        self.contour = to_full(mesh.contours[0])
        self.cell_size = mesh.cell_size / self.mesh_scale
        height, width = mask.shape
        self.uv = (self.vertices + 0.5) / np.array([width, height], dtype=np.float64)
        for array in (self.image, self.mask, self.vertices, self.triangles, self.springs,
                      self.contour, self.uv):
            array.setflags(write=False)

        span = self.vertices.max(0) - self.vertices.min(0)
        self.cells_across = float(max(span) / self.cell_size)
        mass = 1.0
        stiffness, damping, velocity_damping = spring_parameters(self.material,
                                                                 self.cells_across)
        self._no_fold = NoFoldConstraint(self.triangles, self.vertices)
        self.model = MassSpring(self.vertices, self.springs, stiffness=stiffness * mass,
                                damping=damping * mass, mass=mass,
                                velocity_damping=velocity_damping, constraints=[self._no_fold])
        self.state = self.model.state()
        # explicit Verlet is stable below h = 2 / omega_max; Gershgorin bounds omega_max^2 by
        # twice the largest per-node sum of incident stiffness over mass, and along-spring
        # damping needs h * (sum of incident c) / m < 2 as well
        incident = np.bincount(self.springs.ravel(), minlength=len(self.vertices)).max()
        omega_max = math.sqrt(2.0 * stiffness * incident)
        limit = min(2.0 / omega_max, 2.0 / max(2.0 * damping * incident, 1e-12))
        self.max_substep = 0.5 * limit   # [s], half the stability limit
        self._integrator = FrameVerlet(self.model, self._no_fold)
        self._arap: ArapDeformer | None = None
        self._neighbour_lists = None
        self._handle_cache = None
        self.pins: dict[str, Pin] = {}

    # building --------------------------------------------------------------------------
    @classmethod
    def from_image(cls, image, *, cell_size: float | None = None,
                   tolerance: float | None = None, feather: float = 1.5,
                   material="rubber", mode="springs",
                   max_mesh_size: int = DEFAULT_MAX_MESH_SIZE, kind="auto",
                   close_gaps: float | None = None) -> "ImagePuppet":
        """Build a puppet from a picture.

        image : path | (H, W) | (H, W, 3) | (H, W, 4) array (uint8, uint16, float in [0, 1]).
            An alpha channel with transparent parts is used as the character's mask; a plain
            background is keyed out by its colour; a background lit unevenly is modelled as a
            smooth light field, and a pen drawing on paper is filled inside its outline
            (characters/image/background.py)
        kind : "auto" | "alpha" | "plain" | "photo" | "drawing": force one way of finding
            the character (see characters.image.background.PictureKind)
        close_gaps : float [px] | None: a drawing's outline is closed across gaps up to this
            wide (default three stroke widths)
        cell_size : float [px of the picture] grid spacing; default: the character's longer
            side / 24
        tolerance : float [0..255 RGB distance]: how far from the background a colour must
            be to stand out; default from the background's noise
        feather : float [px]: alpha ramp inside the edge (pictures with alpha keep theirs)
        material : "liquid" | "fabric" | "rubber" | "rigid" (characters/materials.toml) or a
            characters.Material with a per-mass stiffness
        mode : "springs" | "arap"
        max_mesh_size : int [px]: pictures with a longer side above this are meshed on a
            downscaled copy of the mask; the mask and image stay full size and the mesh is
            scaled back, so rendering is at full resolution
        """
        require_cv2()
        picture = load_image(image)
        height, width = picture.shape[:2]
        if not isinstance(max_mesh_size, (int, np.integer)) or max_mesh_size < 64:
            raise ValueError(f"max_mesh_size must be an int >= 64 [px], got {max_mesh_size!r}")
        cutout = remove_background(picture, kind=kind, tolerance=tolerance, feather=feather,
                                   close_gaps=close_gaps)
        for note in cutout.notes:
            log.warning(note)
        mask, rgba = cutout.mask, cutout.rgba
        scale = min(1.0, max_mesh_size / max(height, width))
        mask_small = mask
        if scale < 1.0:
            small_size = (max(1, round(width * scale)), max(1, round(height * scale)))
            # a mesh pixel is character if any of the picture's pixels it covers is
            mask_small = shrink_any(mask, small_size)
            scale = small_size[0] / width
            log.info("picture %dx%d meshed at %dx%d", width, height, *small_size)

        ys, xs = np.nonzero(mask_small)
        long_side = max(xs.max() - xs.min(), ys.max() - ys.min()) + 1
        if cell_size is None:
            mesh_cell = max(2.0, long_side / DEFAULT_CELLS_ACROSS)
        else:
            cell_size = float(cell_size)
            if not (cell_size > 0 and math.isfinite(cell_size)):
                raise ValueError(f"cell_size must be a positive width [px], got {cell_size}")
            mesh_cell = cell_size * scale
            if mesh_cell < 2.0:
                raise ValueError(f"cell_size {cell_size:g} px is too small: it must be at least "
                                 f"{2.0 / scale:g} px for this picture")
        # every pixel with some alpha, and its bilinear footprint, lies on the mesh
        mesh = build_grid_mesh(mask_small, mesh_cell, margin=1 if scale == 1.0 else 2)
        return cls(image=rgba, mask=mask, mesh=mesh, mesh_scale=scale, material=material,
                   mode=mode, kind=cutout.kind.value, notes=cutout.notes)

    def _to_picture(self, points: np.ndarray) -> np.ndarray:
        """Mesh-resolution pixel coordinates -> picture pixel coordinates (pixel centres)."""
        return (np.asarray(points, dtype=np.float64) + 0.5) / self.mesh_scale - 0.5

    def _to_mesh(self, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, dtype=np.float64) + 0.5) * self.mesh_scale - 0.5

    # shared puppet interface ---------------------------------------------------------------
    @property
    def faces(self) -> np.ndarray:
        return self.triangles

    @property
    def vertex_count(self) -> int:
        return len(self.vertices)

    @property
    def target_names(self) -> tuple[str, ...]:
        return tuple(name for name, pin in self.pins.items() if not pin.fixed)

    def __repr__(self) -> str:
        height, width = self.mask.shape
        return (f"ImagePuppet({width}x{height} px, {len(self.vertices)} vertices, "
                f"{len(self.triangles)} triangles, {self.mode.value}, {self.material.name}, "
                f"pins {list(self.pins)})")

    def add_pin(self, xy, *, name: str | None = None, fixed: bool = False,
                radius: float | None = None) -> int:
        """Pin the mesh vertex nearest to xy (2,) [px]; returns its index.

        A driven pin (fixed=False) follows `step` targets of that name and relaxes when absent;
        a fixed pin is an anchor held at its rest position. The point must be on the
        character's mesh. The pin holds a small patch: the vertices within `radius` [px]
        (default 1.5 cells: the vertex and its grid neighbours), reached through the mesh,
        moved together; a single pulled vertex would draw a spike and fold the cells beside
        it. radius=0 pins the vertex alone (Animatron's pins)."""
        point = np.asarray(xy, dtype=np.float64).ravel()
        if point.shape != (2,) or not np.all(np.isfinite(point)):
            raise ValueError(f"pin position must be a finite (x, y) in pixels, got {xy!r}")
        if name is None:
            name = f"pin{len(self.pins)}"
        if not isinstance(name, str) or not name:
            raise TypeError(f"pin name must be a non-empty string, got {name!r}")
        if name in self.pins:
            raise ValueError(f"a pin named {name!r} exists already (pins: {list(self.pins)})")
        radius = DEFAULT_PIN_RADIUS * self.cell_size if radius is None else float(radius)
        if not (radius >= 0 and math.isfinite(radius)):
            raise ValueError(f"pin radius must be a distance >= 0 [px], got {radius}")
        distance = np.linalg.norm(self.vertices - point, axis=1)
        index = int(np.argmin(distance))
        if not self._mesh.cells_of(self._to_mesh(point[None]))[0]:
            height, width = self.mask.shape
            where = ("outside the picture" if not (-0.5 <= point[0] < width - 0.5
                                                 and -0.5 <= point[1] < height - 0.5)
                     else "outside the character")
            raise ValueError(f"pin {name!r} at ({point[0]:g}, {point[1]:g}) is {where} "
                             f"({width}x{height} px); the nearest mesh vertex is "
                             f"{distance[index]:.0f} px away at "
                             f"({self.vertices[index, 0]:.0f}, {self.vertices[index, 1]:.0f})")
        region = self._patch(index, radius)
        for other in self.pins.values():
            shared = set(region) & set(other.region)
            if shared:
                what = ("snaps to vertex %d, already used by" % index if index in other.region
                        else "would share vertices with")
                raise ValueError(f"pin {name!r} at ({point[0]:g}, {point[1]:g}) {what} pin "
                                 f"{other.name!r}; place pins at least "
                                 f"{len(region) > 1 and 2 * radius or self.cell_size:.0f} px apart "
                                 f"(or give a smaller radius)")
        self.pins[name] = Pin(name=name, index=index, requested=(float(point[0]),
                                                                 float(point[1])),
                              fixed=bool(fixed), region=tuple(region))
        self._handle_cache = None
        return index

    def _patch(self, index: int, radius: float) -> list[int]:
        """Vertices within radius [px] of vertex `index`, reached along springs inside it."""
        if radius <= 0:
            return [index]
        neighbours = self._neighbours()
        centre = self.vertices[index]
        found, frontier = [index], [index]
        seen = {index}
        while frontier:
            nxt = []
            for vertex in frontier:
                for other in neighbours[vertex]:
                    if other not in seen and np.linalg.norm(self.vertices[other] - centre) <= \
                            radius + 1e-9:
                        seen.add(other)
                        found.append(int(other))
                        nxt.append(other)
            frontier = nxt
        return found

    def _neighbours(self) -> list[np.ndarray]:
        if getattr(self, "_neighbour_lists", None) is None:
            order = np.argsort(np.concatenate([self.springs[:, 0], self.springs[:, 1]]),
                               kind="stable")
            others = np.concatenate([self.springs[:, 1], self.springs[:, 0]])[order]
            counts = np.bincount(np.concatenate([self.springs[:, 0], self.springs[:, 1]]),
                                 minlength=len(self.vertices))
            self._neighbour_lists = np.split(others, np.cumsum(counts)[:-1])
        return self._neighbour_lists

    def propose_pins(self) -> list[ProposedPin]:
        """Pins from the silhouette's skeleton (characters/image/skeleton.py): an anchor
        `body` (fixed) where the body is, and a driven pin at each limb's tip, named by where
        it points: `top`, `bottom_1`, `left`, ... Nothing is added; see `add_auto_pins`."""
        return propose_pins(self.mask)

    def add_auto_pins(self) -> list[str]:
        """Add the proposed pins (`propose_pins`); returns their names, the anchor first.

        A pin holds a patch of at most 1.5 cells, less when another pin is near (a third of
        the distance between them), so that nearby limbs (a horse's front hooves) keep pins
        of their own; a limb too close to another pin even so is left out (logged)."""
        proposed = self.propose_pins()
        points = np.array([pin.xy for pin in proposed])
        added = []
        for index, pin in enumerate(proposed):
            others = np.delete(points, index, axis=0)
            nearest = np.linalg.norm(others - points[index], axis=1).min() if len(others) \
                else np.inf
            radius = min(DEFAULT_PIN_RADIUS * self.cell_size, nearest / 3.0)
            try:
                self.add_pin(pin.xy, name=pin.name, fixed=pin.fixed, radius=radius)
            except ValueError as error:
                log.info("automatic pin %s left out: %s", pin.name, error)
                continue
            added.append(pin.name)
        return added

    def remove_pin(self, name: str) -> None:
        if name not in self.pins:
            raise ValueError(f"no pin named {name!r}; pins are {list(self.pins)}")
        del self.pins[name]
        self._handle_cache = None

    def reset(self) -> None:
        """Back to the rest shape, at rest, t = 0."""
        self.state.x[...] = self.model.rest_positions
        self.state.v[...] = 0.0
        self.state.t = 0.0

    def surface(self) -> np.ndarray:
        """(N, 2) float [px]: the deformed mesh now (a copy)."""
        return self.state.x.copy()

    def handles(self, targets: Mapping[str, np.ndarray] | None):
        """(indices (P,) int, positions (P, 2) float [px]) of the vertices held this step: the
        anchors' patches at rest and the patches of the driven pins named in targets, moved by
        their pin's displacement. Unknown names raise."""
        targets = {} if targets is None else targets
        if not isinstance(targets, Mapping):
            raise TypeError(f"targets must be a dict {{pin name: (x, y)}}, got "
                            f"{type(targets).__name__}")
        indices, positions = [], []
        for name, value in targets.items():
            pin = self.pins.get(name)
            if pin is None or pin.fixed:
                why = ("is a fixed pin (an anchor)" if pin is not None else "is not a pin")
                raise ValueError(f"target {name!r} {why}; this puppet's targets are "
                                 f"{list(self.target_names)}")
            position = np.asarray(value, dtype=np.float64).ravel()
            if position.shape != (2,) or not np.all(np.isfinite(position)):
                raise ValueError(f"target {name!r} must be a finite (x, y) [px], got {value!r}")
            region = np.asarray(pin.region)
            indices.append(region)
            positions.append(self.vertices[region] + (position - self.vertices[pin.index]))
        for pin in self.pins.values():
            if pin.fixed:
                region = np.asarray(pin.region)
                indices.append(region)
                positions.append(self.vertices[region])
        if not indices:
            return np.zeros(0, np.int64), np.zeros((0, 2))
        return np.concatenate(indices).astype(np.int64), np.concatenate(positions)

    def step(self, dt: float, targets: Mapping[str, np.ndarray] | None = None) -> None:
        """Advance by dt [s] with targets {pin name: (2,) position [px]}; a driven pin absent
        from targets relaxes, anchors stay put."""
        dt = float(dt)
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a time step > 0 [s], got {dt}")
        indices, positions = self.handles(targets)
        if self.mode is PuppetMode.ARAP:
            if self._arap is None:
                self._arap = ArapDeformer(self.vertices, self.triangles)
            shape = self._arap.deform(indices, positions)
            self.state.v[...] = (shape - self.state.x) / dt
            self.state.x[...] = shape
            self.state.t += dt
            return
        control = Control(pins=(indices, positions)) if len(indices) else None
        self._integrator.substeps = max(1, math.ceil(dt / self.max_substep))
        self._integrator.step(self.model, self.state, dt, control)
        if len(indices):
            # constraints run after each substep with the model's masses, so the no-fold pass
            # may have nudged a pinned vertex: pins end exactly on their targets
            self.state.x[indices] = positions

    # motions -------------------------------------------------------------------------------
    def check_motion(self, motion) -> None:
        """Raise if the motion names a pin this puppet does not have (or an anchor)."""
        missing = [name for name in motion.channel_names if name not in self.target_names]
        if missing:
            raise ValueError(f"the motion drives {missing} but this puppet has no driven pin of "
                             f"that name; its driven pins are {list(self.target_names)}")
        for name in motion.channel_names:
            if motion.channel_size(name) != 2:
                raise ValueError(f"motion channel {name!r} has {motion.channel_size(name)} "
                                 f"values per key; image puppet pins need (x, y)")

    def simulate(self, motion, *, fps: float, duration: float | None = None) -> np.ndarray:
        """Reset, then play a motion frame by frame: (T, N, 2) float [px] shapes at
        t = 0, 1/fps, ... up to duration (default the motion's)."""
        self.check_motion(motion)
        duration = motion.duration if duration is None else float(duration)
        count = int(math.floor(duration * fps + 1e-9)) + 1
        shapes = np.empty((count, len(self.vertices), 2))
        self.reset()
        self._arap_first(motion)
        shapes[0] = self.state.x
        for frame in range(1, count):
            self.step(1.0 / fps, motion.sample(frame / fps))
            shapes[frame] = self.state.x
        return shapes

    def _arap_first(self, motion) -> None:
        """ARAP frames are a function of the pins: frame 0 is the pose at t = 0 too."""
        if self.mode is PuppetMode.ARAP and motion.channel_names:
            self.step(1.0, motion.sample(0.0))
            self.state.v[...] = 0.0
            self.state.t = 0.0

    def bake(self, motion, *, fps: float = 25.0, max_interval: float = 0.1,
             duration: float | None = None) -> BakedMotion:
        """Simulate a motion and keep the mesh at key times only (see characters/image/bake.py):
        where a pin movement starts or ends (the motion's key times) and at most max_interval
        [s] apart in between. Returns a BakedMotion whose `deviation` reports how far linear
        blending strays from the full simulation."""
        self.check_motion(motion)
        shapes = self.simulate(motion, fps=fps, duration=duration)
        return bake_motion(motion, shapes, fps=fps, max_interval=max_interval)

    def inverted_triangles(self, positions: np.ndarray | None = None) -> np.ndarray:
        """(K,) int: triangles whose signed area is <= 0 at positions (default: now)."""
        x = self.state.x if positions is None else positions
        return np.flatnonzero(signed_areas(x, self.triangles) <= 0.0)


class FrameVerlet(Verlet):
    """Verlet stepping an image puppet: with pins only (no target pulls or external forces)
    all substeps of a step run in one compiled call (`frame.run_substeps`: the same kernels in
    the same order as the base class's loop, Python's lock released); the checks, rollback and
    retries stay the base class's, once per step."""

    def __init__(self, model: MassSpring, guard: NoFoldConstraint, **options):
        super().__init__(**options)
        self._model = model
        self._guard = guard
        compiled = model.dim == 2 and list(model.constraints) == [guard]
        self._frame = FrameArrays.of(model, guard) if compiled else None

    def _run(self, model, state, dt, control, substeps, scratch) -> int:
        if (self._frame is None or model is not self._model or control.target_index.size
                or control.force_index.size):
            return super()._run(model, state, dt, control, substeps, scratch)
        h = dt / substeps
        self._guard.last_below = int(run_substeps(
            self._frame, state.x, state.v, scratch.x0, control.pin_index, control.pin_position,
            substeps, h, math.exp(-model.velocity_damping * h)))
        return 0
