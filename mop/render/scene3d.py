"""Offscreen 3D rendering of deformable puppets with pyrender (EGL, no display, no GPU needed).

    with Scene3D(size=(720, 576), camera="three_quarter", background="chroma") as scene:
        scene.add(puppet)                  # anything with surface() -> (V, 3) and faces (F, 3)
        for frame in range(100):
            puppet.step(1 / 25, targets)
            scene.update()                 # new vertex positions (and normals) only
            rgba = scene.render()          # (H, W, 4) uint8, straight alpha

The scene (meshes, material, lights, camera) is built once; per frame only the vertex buffer
of each mesh is rewritten in place (glBufferSubData of positions + normals), never rebuilt.
The renderer is pyrender's, with two changes that matter on a software rasteriser (Mesa
llvmpipe): the frame is read back as colour only (pyrender also reads and converts depth),
and multisampling is optional (`antialias=True` for stills, off by default for live frames);
see benchmarks/latex_puppet.py for the measured effect. Close the scene (or use `with`) to free
the OpenGL context.

Backgrounds: "transparent" (alpha 0 around the puppet), "chroma" (pure key green, opaque, for a
vision mixer's chroma keyer), "blue" (key blue), "#rrggbb" or (r, g, b) in 0..255.
"""
from __future__ import annotations

import os
import threading

# pyrender picks its OpenGL platform when OpenGL is first imported: EGL works headless.
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from mop import export  # noqa: E402

if not hasattr(np, "infty"):  # pyrender 0.1.45 still uses np.infty, removed in NumPy 2
    np.infty = np.inf

try:  # noqa: E402
    import pyrender
    from OpenGL import GL
    from pyrender.renderer import Renderer as _PyrenderRenderer
except ImportError as _error:  # pragma: no cover - depends on the environment
    raise ImportError("3D rendering needs pyrender: pip install 'mop[render3d]'") from _error


_JIT = dict(cache=True, nogil=True, error_model="numpy")


class _OrderedScene(pyrender.Scene):
    """A pyrender scene that hands meshes and lights to the renderer in the order they were
    added. pyrender keeps them in sets, whose order follows object ids and so changes from run to
    run; the shader then sums the lights in another order and a few pixels round one level
    differently, which breaks byte-identical replays."""

    def __init__(self, **kwargs):
        self._added = {}
        super().__init__(**kwargs)

    def add_node(self, node, parent_node=None):
        self._added.setdefault(node, len(self._added))
        super().add_node(node, parent_node=parent_node)

    def remove_node(self, node):
        super().remove_node(node)
        self._added.pop(node, None)

    def _ordered(self, nodes):
        return sorted(nodes, key=lambda n: self._added.get(n, -1))

    @property
    def mesh_nodes(self):
        return self._ordered(super().mesh_nodes)

    @property
    def light_nodes(self):
        return self._ordered(super().light_nodes)


@dataclass(frozen=True)
class Look:
    """A surface material: base colour (r, g, b) in 0..1, roughness, metallic, and whether
    vertex colours (when the mesh has them) tint the base colour. Closed surfaces draw their
    front faces only (back-face culling halves a software rasteriser's work); set double_sided
    for open or cut meshes."""

    base_color: tuple = (0.42, 0.68, 0.32)
    roughness: float = 0.38
    metallic: float = 0.0
    use_vertex_colors: bool = True
    double_sided: bool = False


#: Named looks. "latex": painted latex rubber, a soft sheen; "matte": foam / cloth; "clay".
LOOKS = {
    "latex": Look((1.0, 1.0, 1.0), roughness=0.36),
    "matte": Look((1.0, 1.0, 1.0), roughness=0.9),
    "clay": Look((0.78, 0.62, 0.5), roughness=0.7, use_vertex_colors=False),
}

#: Camera directions (from the subject towards the camera; +y up, +z front).
CAMERAS = {
    "front": (0.0, 0.12, 1.0),
    "three_quarter": (0.62, 0.32, 0.85),
    "side": (1.0, 0.1, 0.0),
    "top": (0.0, 1.0, 0.35),
    "below": (0.2, -0.6, 0.8),
}

def parse_background(background) -> tuple[float, float, float, float]:
    """Anything `mop.export.parse_background` takes -> pyrender's (r, g, b, a) in 0..1
    (transparent: alpha 0)."""
    rgb = export.parse_background(background)
    if rgb is None:
        return (0.0, 0.0, 0.0, 0.0)
    return (*(c / 255.0 for c in rgb), 1.0)


@njit(**_JIT)
def vertex_normals(x, faces, out):
    """Area-weighted unit vertex normals out (V, 3) of positions x (V, 3) and faces (F, 3)."""
    out[:] = 0.0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ux = x[b, 0] - x[a, 0]
        uy = x[b, 1] - x[a, 1]
        uz = x[b, 2] - x[a, 2]
        vx = x[c, 0] - x[a, 0]
        vy = x[c, 1] - x[a, 1]
        vz = x[c, 2] - x[a, 2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        for i in (a, b, c):
            out[i, 0] += nx
            out[i, 1] += ny
            out[i, 2] += nz
    for i in range(out.shape[0]):
        length = np.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
        if length > 0.0:
            out[i, 0] /= length
            out[i, 1] /= length
            out[i, 2] /= length


@njit(**_JIT)
def _pack_vertices(x, normals, buffer):
    """Write positions and normals into the interleaved float32 vertex buffer (V, stride)."""
    for i in range(x.shape[0]):
        for k in range(3):
            buffer[i, k] = x[i, k]
            buffer[i, 3 + k] = normals[i, k]


class _LeanRenderer(_PyrenderRenderer):
    """pyrender's renderer reading back colour only, with a configurable multisample count."""

    samples = 0

    def _configure_main_framebuffer(self):
        if self._main_fb is not None and (self.viewport_width != self._main_fb_dims[0]
                                          or self.viewport_height != self._main_fb_dims[1]):
            self._delete_main_framebuffer()
        if self._main_fb is not None:
            return
        width, height = self.viewport_width, self.viewport_height
        self._main_cb, self._main_db = GL.glGenRenderbuffers(2)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, self._main_cb)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_RGBA, width, height)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, self._main_db)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_DEPTH_COMPONENT24, width, height)
        self._main_fb = GL.glGenFramebuffers(1)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0,
                                     GL.GL_RENDERBUFFER, self._main_cb)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT,
                                     GL.GL_RENDERBUFFER, self._main_db)
        if self.samples == 0:
            # no multisampling: draw straight into the framebuffer that is read back (saves a
            # full-frame blit); pyrender draws into _main_fb_ms
            self._main_fb_ms, self._main_cb_ms, self._main_db_ms = (
                self._main_fb, self._main_cb, self._main_db)
            self._main_fb_dims = (width, height)
            return
        self._main_cb_ms, self._main_db_ms = GL.glGenRenderbuffers(2)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, self._main_cb_ms)
        GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, self.samples, GL.GL_RGBA,
                                            width, height)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, self._main_db_ms)
        GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, self.samples,
                                            GL.GL_DEPTH_COMPONENT24, width, height)
        self._main_fb_ms = GL.glGenFramebuffers(1)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb_ms)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0,
                                     GL.GL_RENDERBUFFER, self._main_cb_ms)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT,
                                     GL.GL_RENDERBUFFER, self._main_db_ms)
        self._main_fb_dims = (width, height)

    def _delete_main_framebuffer(self):
        if self.samples == 0 and self._main_fb is not None:
            GL.glDeleteFramebuffers(1, [self._main_fb])
            GL.glDeleteRenderbuffers(2, [self._main_cb, self._main_db])
            self._main_fb = self._main_cb = self._main_db = None
            self._main_fb_ms = self._main_cb_ms = self._main_db_ms = None
            self._main_fb_dims = (None, None)
            return
        super()._delete_main_framebuffer()

    def _read_main_framebuffer(self, scene, flags):
        width, height = self._main_fb_dims
        if self._main_fb_ms != self._main_fb:  # resolve the multisampled frame
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
            GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height,
                                 GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb)
        data = GL.glReadPixels(0, 0, width, height, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE)
        image = np.frombuffer(data, dtype=np.uint8).reshape(height, width, 4)
        return image[::-1], None


class _Offscreen(pyrender.OffscreenRenderer):
    """pyrender's offscreen renderer with the lean renderer, and a delete() that keeps the EGL
    display alive while other scenes of the process still use it (pyrender terminates the
    shared display, which breaks every other open context)."""

    _open = 0
    _lock = threading.Lock()

    def __init__(self, width, height, samples):
        self._samples = samples
        super().__init__(width, height)

    def _create(self):
        super()._create()
        self._renderer.delete()
        self._renderer = _LeanRenderer(self.viewport_width, self.viewport_height)
        self._renderer.samples = self._samples
        with _Offscreen._lock:
            _Offscreen._open += 1

    def delete(self):
        platform = self._platform
        if platform is None:
            return
        platform.make_current()
        self._renderer.delete()
        with _Offscreen._lock:
            _Offscreen._open -= 1
            last = _Offscreen._open == 0
        if last or not hasattr(platform, "_egl_display"):
            platform.delete_context()
        else:
            from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent
            eglMakeCurrent(platform._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)
            eglDestroyContext(platform._egl_display, platform._egl_context)
            platform._egl_context = None
            platform._egl_display = None  # so the platform's __del__ does not terminate it
        self._renderer = None
        self._platform = None


class _Item:
    """One mesh in the scene and the buffers its per-frame update reuses."""

    def __init__(self, source, faces, colors, look: Look, name: str):
        self.source = source
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.name = name
        positions = self._positions()
        self.normals = np.empty_like(positions)
        vertex_normals(positions, self.faces, self.normals)
        kwargs = dict(positions=positions.astype(np.float32),
                      normals=self.normals.astype(np.float32),
                      indices=self.faces.astype(np.uint32))
        if colors is not None and look.use_vertex_colors:
            colors = np.asarray(colors)
            if colors.shape != (len(positions), 4) and colors.shape != (len(positions), 3):
                raise ValueError(f"colors must have shape ({len(positions)}, 3|4), got "
                                 f"{colors.shape}")
            rgba = np.ones((len(positions), 4), dtype=np.float32)
            scale = 255.0 if colors.dtype == np.uint8 else 1.0
            rgba[:, :colors.shape[1]] = colors / scale
            # pyrender's shader takes vertex colours as linear: undo the sRGB encoding
            rgba[:, :3] = np.where(rgba[:, :3] <= 0.04045, rgba[:, :3] / 12.92,
                                   ((rgba[:, :3] + 0.055) / 1.055) ** 2.4)
            kwargs["color_0"] = rgba
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=(*look.base_color, 1.0), metallicFactor=look.metallic,
            roughnessFactor=look.roughness, doubleSided=look.double_sided)
        self.primitive = pyrender.Primitive(material=material, **kwargs)
        self.mesh = pyrender.Mesh([self.primitive], name=name)
        stride = 6 + (4 if "color_0" in kwargs else 0)
        self.buffer = np.zeros((len(positions), stride), dtype=np.float32)
        self.buffer[:, :3] = positions
        self.buffer[:, 3:6] = self.normals
        if "color_0" in kwargs:
            self.buffer[:, 6:10] = kwargs["color_0"]
        self.rest_bounds = np.stack([positions.min(0), positions.max(0)])

    def _positions(self, vertices=None) -> np.ndarray:
        if vertices is None:
            vertices = self.source.surface() if hasattr(self.source, "surface") else self.source
        vertices = np.asarray(vertices, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"{self.name}: vertices must have shape (V, 3), got {vertices.shape}")
        return vertices

    def refresh(self, vertices=None) -> None:
        x = self._positions(vertices)
        if x.shape[0] != self.buffer.shape[0]:
            raise ValueError(f"{self.name}: expected {self.buffer.shape[0]} vertices, got "
                             f"{x.shape[0]}")
        vertex_normals(x, self.faces, self.normals)
        _pack_vertices(x, self.normals, self.buffer)


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera pose (4, 4): camera at eye looking at target, +y up (pyrender looks along -z)."""
    forward = target - eye
    forward /= np.linalg.norm(forward)
    up = np.array([0.0, 1.0, 0.0])
    if abs(forward @ up) > 0.99:
        up = np.array([0.0, 0.0, -1.0])
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    pose = np.eye(4)
    pose[:3, 0] = right
    pose[:3, 1] = true_up
    pose[:3, 2] = -forward
    pose[:3, 3] = eye
    return pose


class Scene3D:
    """A pyrender scene built once; meshes' vertices change per frame.

    size : (width, height) [px]; camera : a CAMERAS name or a (4, 4) camera pose;
    background : see `parse_background`; antialias : 4x multisampling
    (slower on software rasterisers); yfov : vertical field of view [rad];
    lights : "studio" (key, fill, rim directional lights) or "flat" (one headlight).
    """

    def __init__(self, *, size=(720, 576), camera="three_quarter", background="transparent",
                 antialias: bool = False, yfov: float = 0.55, lights: str = "studio"):
        width, height = (int(v) for v in size)
        if width < 1 or height < 1:
            raise ValueError(f"size must be (width, height) >= 1 px, got {size}")
        if not isinstance(camera, str) and np.asarray(camera).shape != (4, 4):
            raise ValueError(f"camera must be one of {sorted(CAMERAS)} or a (4, 4) pose, got "
                             f"{camera!r}")
        if isinstance(camera, str) and camera not in CAMERAS:
            raise ValueError(f"camera must be one of {sorted(CAMERAS)} or a (4, 4) pose, got "
                             f"{camera!r}")
        if lights not in ("studio", "flat"):
            raise ValueError(f"lights must be 'studio' or 'flat', got {lights!r}")
        self.size = (width, height)
        self.background = parse_background(background)
        self._camera_choice = camera
        self._lights = lights
        self._yfov = float(yfov)
        self._scene = _OrderedScene(bg_color=self.background, ambient_light=(0.28, 0.28, 0.3))
        self._items: list[_Item] = []
        self._camera_node = None
        self._light_nodes = []
        self._renderer = _Offscreen(width, height, 4 if antialias else 0)
        self._frames = 0

    # --- building ----------------------------------------------------------------------------
    def add(self, item, faces=None, *, colors=None, look="latex", name: str | None = None) -> int:
        """Add a puppet (anything with surface() and faces, optionally vertex_colors) or a
        vertex array (V, 3) with faces (F, 3). Returns its handle for update()."""
        self._check_open()
        if isinstance(look, str):
            if look not in LOOKS:
                raise ValueError(f"look must be one of {sorted(LOOKS)} or a Look, got {look!r}")
            look = LOOKS[look]
        elif not isinstance(look, Look):
            raise TypeError(f"look must be a name or a Look, got {type(look).__name__}")
        if faces is None:
            if not hasattr(item, "surface") or not hasattr(item, "faces"):
                raise TypeError(f"add() takes a puppet (surface(), faces) or vertices with "
                                f"faces=, got {type(item).__name__}")
            faces = item.faces
            if colors is None:
                colors = getattr(item, "vertex_colors", None)
        name = name or f"mesh{len(self._items)}"
        entry = _Item(item, faces, colors, look, name)
        self._scene.add(entry.mesh, name=name)
        self._items.append(entry)
        if self._camera_node is None:
            self.frame()
        return len(self._items) - 1

    def frame(self, bounds: np.ndarray | None = None, *, margin: float = 1.15) -> None:
        """Point the camera (and the lights) at bounds (2, 3) [m], default all meshes at rest."""
        if bounds is None:
            if not self._items:
                raise ValueError("nothing to frame: add a mesh first or pass bounds")
            stacked = np.concatenate([item.rest_bounds for item in self._items])
            bounds = np.stack([stacked.min(0), stacked.max(0)])
        bounds = np.asarray(bounds, dtype=np.float64)
        centre = bounds.mean(0)
        radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
        aspect = self.size[0] / self.size[1]
        half = self._yfov / 2 if aspect >= 1 else np.arctan(np.tan(self._yfov / 2) * aspect)
        distance = margin * radius / np.sin(half)
        if isinstance(self._camera_choice, str):
            direction = np.asarray(CAMERAS[self._camera_choice], dtype=np.float64)
            direction /= np.linalg.norm(direction)
            pose = _look_at(centre + direction * distance, centre)
        else:
            pose = np.asarray(self._camera_choice, dtype=np.float64)
        camera = pyrender.PerspectiveCamera(yfov=self._yfov, aspectRatio=aspect,
                                            znear=distance * 0.05, zfar=distance * 4)
        if self._camera_node is not None:
            self._scene.remove_node(self._camera_node)
        for node in self._light_nodes:
            self._scene.remove_node(node)
        self._camera_node = self._scene.add(camera, pose=pose)
        self._light_nodes = []
        if self._lights == "flat":
            self._light_nodes.append(self._scene.add(
                pyrender.DirectionalLight(intensity=3.0), pose=pose))
            return
        for offset, intensity in (((0.5, 0.6, 0.0), 3.2), ((-0.7, 0.1, 0.0), 1.2),
                                  ((0.0, 0.5, -1.6), 2.0)):
            eye = pose[:3, 3] + pose[:3, :3] @ (np.asarray(offset) * distance)
            self._light_nodes.append(self._scene.add(
                pyrender.DirectionalLight(color=(1.0, 0.97, 0.92), intensity=intensity),
                pose=_look_at(eye, centre)))

    # --- per frame -----------------------------------------------------------------------------
    def update(self, handle: int | None = None, vertices: np.ndarray | None = None) -> None:
        """Take new vertex positions: of one handle (vertices (V, 3) [m], or the puppet's
        surface() when None), or of every puppet when handle is None."""
        self._check_open()
        items = self._items if handle is None else [self._items[handle]]
        for item in items:
            item.refresh(vertices if handle is not None else None)
        if self._frames == 0:
            for item in items:
                item.primitive.positions = item.buffer[:, :3].copy()
                item.primitive.normals = item.buffer[:, 3:6].copy()
            return
        self._renderer._platform.make_current()
        for item in items:
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, item.primitive._buffers[0])
            GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, item.buffer.nbytes, item.buffer)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)

    def render(self) -> np.ndarray:
        """The current frame, (H, W, 4) uint8 RGBA with straight alpha."""
        self._check_open()
        if not self._items:
            raise ValueError("the scene is empty: add a mesh before rendering")
        flags = pyrender.RenderFlags.RGBA
        color, _ = self._renderer.render(self._scene, flags=flags)
        self._frames += 1
        return np.array(color)  # own the pixels: GL reuses its buffer

    # --- life cycle ----------------------------------------------------------------------------
    def release(self) -> None:
        """Make no GL context current in the calling thread, so that another thread may draw
        this scene next (an EGL context is current in one thread at a time; pyrender makes it
        current again on its next use)."""
        platform = None if self._renderer is None else self._renderer._platform
        display = getattr(platform, "_egl_display", None)
        if display is None:
            return
        from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglMakeCurrent
        eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)

    def close(self) -> None:
        """Free the OpenGL context and buffers (idempotent)."""
        if self._renderer is not None:
            self._renderer.delete()
            self._renderer = None

    @property
    def closed(self) -> bool:
        return self._renderer is None

    def _check_open(self) -> None:
        if self._renderer is None:
            raise ValueError("this Scene3D is closed")

    def __enter__(self) -> "Scene3D":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # a forgotten close() must not leak the EGL context
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown: GL may be gone already
            pass

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"{len(self._items)} meshes"
        return f"Scene3D({self.size[0]}x{self.size[1]}, {state})"


def record(puppet, targets, path, *, fps: float = 25.0, size=(720, 576),
           camera="three_quarter", background="chroma", antialias: bool = False) -> int:
    """Step a puppet through `targets` (an iterable of {name: value} dicts, one per frame) and
    write each rendered frame to `path` through mop.export.open_writer (video, GIF or PNG
    sequence, chosen by the path). Returns the number of frames written."""
    from mop.export import open_writer
    fps = float(fps)
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    count = 0
    with Scene3D(size=size, camera=camera, background=background, antialias=antialias) as scene, \
            open_writer(path, fps=fps, size=tuple(size),
                        background=None if background == "transparent" else background) as writer:
        handle = scene.add(puppet)
        for frame_targets in targets:
            puppet.step(1.0 / fps, frame_targets)
            scene.update(handle)
            writer.write(scene.render())
            count += 1
    return count
