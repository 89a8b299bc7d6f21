"""Characters of a session: the registry of puppet kinds, each kind's builder and its layer.

    KINDS[CharacterKind.LATEX](character, height) -> (puppet, layer renderer)

A puppet satisfies `characters.Puppet`. A layer renderer has `render(puppet) -> (h, w, 4)
uint8 RGBA` (straight alpha) and `close()`; its height is the character's `scale` x the frame
height, its width follows the character. A new kind is a package under `characters/` plus a
builder here registered with `@register(CharacterKind.NAME)` (and the name in
`config.CharacterKind`, the closed set a session file may name).

Per-kind options (`[characters.NAME.options]` in the session file):

- image: `pins = {name = [x, y]}` driven pins and `anchors = {name = [x, y]}` fixed ones, in
  picture pixels (default: the picture's `NAME.pins.json` beside it, if any); `cell_size` [px],
  `mode` ("springs" | "arap"); `material` is the image puppet's ("liquid", "fabric", "rubber",
  "rigid").
- latex: anything `LatexPuppet.from_mesh` accepts (e.g. `masses`, `materials` = one preset per
  layer); the asset "froggy" is the shipped frog head (`LatexPuppet.froggy`).
- medial: `joints` (a joints JSON path or the list of cuts), `constraint`; `material` is a
  medial preset ("thick skin", "water", "plastic", "skin", "tight cloth").
- all 3D kinds: `camera` = "front" | "three_quarter" | "side" | "top" | "below" (the
  direction the character is seen from; default "three_quarter").
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from .config import CharacterConfig, CharacterKind, SessionError

LAYER_MARGIN = 0.12   # free border around a character in its layer [fraction of its size]


#: (character, layer height [px]) -> (puppet, layer renderer): one builder per kind
Builder = Callable[[CharacterConfig, int], tuple]

KINDS: dict[CharacterKind, Builder] = {}


def register(kind: CharacterKind):
    """Decorator: the function becomes the builder of `kind`."""
    def decorate(build: Builder) -> Builder:
        if kind in KINDS:
            raise ValueError(f"puppet kind {kind.value!r} is registered already")
        KINDS[kind] = build
        return build
    return decorate


def data_folder() -> Path:
    import characters
    return Path(characters.__file__).resolve().parent / "assets"


def resolve_asset(character: CharacterConfig, suffixes: tuple[str, ...]) -> Path:
    """A path as given, or a file shipped in characters/assets/ named `asset` + a known suffix."""
    path = Path(character.asset)
    if path.exists():
        return path
    folder = data_folder()
    candidates = [folder / f"{character.asset}{suffix}" for suffix in suffixes]
    candidates += [folder / character.asset / f"{character.asset}{suffix}" for suffix in suffixes]
    for candidate in candidates:
        if candidate.exists():
            return candidate
    shipped = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
    raise SessionError(
        f"characters.{character.name}.asset: no file {character.asset!r} and no shipped asset of "
        f"that name with {', '.join(suffixes)} in {folder} (it has {', '.join(shipped) or 'none'})")


def _option(character: CharacterConfig, name: str, kind, default=None):
    value = character.options.get(name, default)
    if value is not None and not isinstance(value, kind):
        raise SessionError(f"characters.{character.name}.options.{name}: expected "
                           f"{getattr(kind, '__name__', kind)}, got {value!r}")
    return value


def _points(character: CharacterConfig, name: str) -> dict[str, tuple[float, float]]:
    table = _option(character, name, dict, {})
    points = {}
    for key, value in table.items():
        if (not isinstance(value, list) or len(value) != 2
                or not all(isinstance(v, (int, float)) for v in value)):
            raise SessionError(f"characters.{character.name}.options.{name}.{key}: expected "
                               f"[x, y] in picture pixels, got {value!r}")
        points[key] = (float(value[0]), float(value[1]))
    return points


def build(character: CharacterConfig, *, frame_height: int):
    """(puppet, layer renderer) for one character."""
    height = max(8, int(round(character.scale * frame_height)))
    builder = KINDS.get(character.kind)
    if builder is None:
        raise SessionError(f"characters.{character.name}.kind: no builder registered for "
                           f"{character.kind.value!r}; registered: "
                           f"{', '.join(k.value for k in KINDS)}")
    return builder(character, height)


# 2D image puppets ----------------------------------------------------------------------------

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp")


@register(CharacterKind.IMAGE)
def _image(character: CharacterConfig, height: int):
    from characters import ImagePuppet
    path = resolve_asset(character, IMAGE_SUFFIXES)
    known = {"pins", "anchors", "cell_size", "mode"}
    unknown = set(character.options) - known
    if unknown:
        raise SessionError(f"characters.{character.name}.options.{sorted(unknown)[0]}: unknown "
                           f"option for an image character; expected one of "
                           f"{', '.join(sorted(known))}")
    options = {}
    if character.material:
        options["material"] = character.material
    if "cell_size" in character.options:
        options["cell_size"] = float(_option(character, "cell_size", (int, float)))
    if "mode" in character.options:
        options["mode"] = _option(character, "mode", str)
    puppet = ImagePuppet.from_image(str(path), **options)
    pins, anchors = _points(character, "pins"), _points(character, "anchors")
    sidecar = path.with_name(path.stem + ".pins.json")
    if not pins and not anchors and sidecar.exists():
        pins, anchors = read_pins(sidecar)
    for name, xy in pins.items():
        puppet.add_pin(xy, name=name)
    for name, xy in anchors.items():
        puppet.add_pin(xy, name=name, fixed=True)
    return puppet, ImageLayer(puppet, height=height)


def read_pins(path: Path) -> tuple[dict, dict]:
    """({driven pin: (x, y)}, {anchor: (x, y)}) from a shipped `NAME.pins.json`
    ({"format": "mop.pins", "pins": {name: {"xy": [x, y], "fixed": bool}}}; strict, see
    `mop.sidecars`)."""
    from mop.sidecars import read_pins as read
    pins, anchors = {}, {}
    for name, pin in read(path).items():
        (anchors if pin.fixed else pins)[name] = pin.xy
    return pins, anchors


class ImageLayer:
    """An image puppet drawn into its own layer by `mop.render.image2d.ImageRenderer`: the rest
    mesh's bounding box plus a margin fills the layer height."""

    def __init__(self, puppet, *, height: int, margin: float = LAYER_MARGIN):
        from mop.render.image2d import ImageRenderer
        low, high = puppet.vertices.min(0), puppet.vertices.max(0)
        span = high - low
        self.scale = height / (span[1] * (1 + 2 * margin))
        width = int(round(span[0] * (1 + 2 * margin) * self.scale))
        width += width % 2
        self.offset = (low + high) / 2
        self.centre = np.array([width / 2, height / 2])
        self.renderer = ImageRenderer(np.ascontiguousarray(puppet.image), puppet.vertices,
                                      puppet.triangles, size=(width, height),
                                      background="transparent")
        self.frame = np.zeros((height, width, 4), np.uint8)
        self._xy = np.empty_like(puppet.vertices)

    def render(self, puppet) -> np.ndarray:
        xy = self._xy
        np.subtract(puppet.state.x, self.offset, out=xy)
        xy *= self.scale
        xy += self.centre
        return self.renderer.render_into(xy, self.frame)

    def close(self) -> None:
        pass


# 3D puppets -----------------------------------------------------------------------------------

class SceneLayer:
    """A 3D puppet drawn by `mop.render.scene3d.Scene3D` (OpenGL, offscreen) into its own
    square transparent layer; the scene is built once and only vertices change per frame."""

    def __init__(self, puppet, *, height: int, colour=None, camera: str = "three_quarter"):
        from mop.render.scene3d import Look, Scene3D
        size = int(height) + int(height) % 2
        self.scene = Scene3D(size=(size, size), camera=camera, background="transparent")
        if colour is not None and getattr(puppet, "vertex_colors", None) is None:
            look = Look(tuple(c / 255.0 for c in colour), roughness=0.45,
                        use_vertex_colors=False)
        else:
            look = "latex"
        self.scene.add(puppet, look=look)
        self._options = dict(height=height, colour=colour, camera=camera)
        self._shape = puppet

    def recipe(self):
        """How to build this layer again in a render process: the puppet's mesh at rest and the
        same options (the GL context itself cannot travel)."""
        from .worker import MeshShape
        return (SceneLayer, (MeshShape(self._shape),), self._options)

    def render(self, puppet) -> np.ndarray:
        # the vertices of the puppet handed in: a session's render worker hands a frozen copy
        self.scene.update(0, puppet.surface())
        return self.scene.render()

    def release(self) -> None:
        """Let another thread draw this layer next (see Scene3D.release)."""
        self.scene.release()

    def close(self) -> None:
        self.scene.close()


def _mesh_layer(character: CharacterConfig, puppet, height: int, colour):
    camera = _option(character, "camera", str, "three_quarter")
    return SceneLayer(puppet, height=height, colour=colour, camera=camera)


LATEX_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb")


@register(CharacterKind.LATEX)
def _latex(character: CharacterConfig, height: int):
    from characters import LatexPuppet
    options = {k: v for k, v in character.options.items() if k != "camera"}
    if character.material:
        raise SessionError(f"characters.{character.name}.material: a latex puppet has one "
                           f"material per layer; give options.materials = [skin, foam, cavity] "
                           f"instead")
    if character.asset == "froggy" and not Path(character.asset).exists():
        puppet = LatexPuppet.froggy(**options)        # the shipped frog head
    else:
        path = resolve_asset(character, LATEX_SUFFIXES)
        puppet = LatexPuppet.from_mesh(str(path), **options)
    return puppet, _mesh_layer(character, puppet, height, character.colour)


MEDIAL_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb")


@register(CharacterKind.MEDIAL)
def _medial(character: CharacterConfig, height: int):
    from characters import MedialObject
    options = {k: v for k, v in character.options.items() if k != "camera"}
    if character.material:
        options["material"] = character.material
    path = resolve_asset(character, MEDIAL_SUFFIXES)
    joints = options.get("joints")
    if isinstance(joints, str) and not Path(joints).is_absolute():
        for base in (path.parent, data_folder()):
            if (base / joints).exists():
                options["joints"] = str(base / joints)
                break
    elif joints is None:
        sidecar = path.with_name(path.stem + ".joints.json")
        if sidecar.exists():
            options["joints"] = str(sidecar)
    puppet = MedialObject.from_mesh(str(path), **options)
    return puppet, _mesh_layer(character, puppet, height, character.colour or (206, 120, 160))
