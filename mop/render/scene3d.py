"""Offscreen 3D rendering of deformable puppets with OpenGL through moderngl (EGL: no display,
no GPU needed; Mesa's llvmpipe rasterises in software).

    with Scene3D(size=(720, 576), camera="three_quarter", background="chroma") as scene:
        scene.add(puppet)                  # anything with surface() -> (V, 3) and faces (F, 3)
        for frame in range(100):
            puppet.step(1 / 25, targets)
            scene.update()                 # new vertex positions (and normals) only
            rgba = scene.render()          # (H, W, 4) uint8, straight alpha

The scene (meshes, materials, lights, camera) is built once; per frame only the vertex buffer
of each mesh is rewritten in place, never rebuilt. Meshes are drawn in the order they were
added, so the same input gives the same pixels on every run. Shading is the glTF 2.0
metallic-roughness model (GGX distribution, Schlick-GGX geometry, Schlick Fresnel) under
directional lights and an ambient term, written out with a 2.2 gamma. Multisampling is optional
(`antialias=True` for stills, off by default for live frames: on a software rasteriser it more
than doubles a frame's cost). Each scene owns its OpenGL context, made current around every
call, so a scene may be used from any thread (one at a time). Close the scene (or use `with`)
to free it.

Backgrounds: "transparent" (alpha 0 around the puppet), "chroma" (pure key green, opaque, for a
vision mixer's chroma keyer), "blue" (key blue), "#rrggbb" or (r, g, b) in 0..255.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numba import njit

from mop import export

try:
    import moderngl
except ImportError as _error:  # pragma: no cover - depends on the environment
    raise ImportError("3D rendering needs moderngl: pip install 'mop[render3d]'") from _error


_JIT = dict(cache=True, nogil=True, error_model="numpy")
_STRIDE = 10          # floats per vertex in the buffer: position (3), normal (3), colour (4)
_MAX_LIGHTS = 3

_VERTEX_SHADER = """
#version 330
uniform mat4 view_projection;
in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;
out vec3 v_position;
out vec3 v_normal;
out vec4 v_color;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_color = in_color;
    gl_Position = view_projection * vec4(in_position, 1.0);
}
"""

# glTF 2.0 metallic-roughness: a Lambert diffuse lobe and a GGX specular lobe with Schlick's
# Fresnel term and the Schlick-GGX geometry term with k = (roughness + 1)^2 / 8 (the common
# real-time choice for direct light), in linear light, written out with a 2.2 gamma. Vertex
# colours multiply the lit colour rather than the base colour: a painted pupil stays matte.
_FRAGMENT_SHADER = """
#version 330
const float PI = 3.141592653589793;
uniform vec3 camera_position;
uniform vec4 base_color_factor;
uniform float metallic;
uniform float roughness;
uniform int light_count;
uniform vec3 light_direction[3];     // unit vectors from the surface towards each light
uniform vec3 light_radiance[3];      // colour x intensity
uniform vec3 ambient;
in vec3 v_position;
in vec3 v_normal;
in vec4 v_color;
out vec4 frag_color;

void main() {
    vec4 base = base_color_factor;
    vec3 n = normalize(v_normal);
    vec3 v = normalize(camera_position - v_position);
    float perceptual = clamp(roughness, 0.04, 1.0);
    float alpha2 = pow(perceptual, 4.0);
    float k = (perceptual + 1.0) * (perceptual + 1.0) / 8.0;
    vec3 f0 = mix(vec3(0.04), base.rgb, metallic);
    vec3 diffuse_color = mix(base.rgb * (1.0 - 0.04), vec3(0.0), metallic);
    float n_dot_v = clamp(abs(dot(n, v)), 0.001, 1.0);
    vec3 color = vec3(0.0);
    for (int i = 0; i < light_count; ++i) {
        vec3 l = light_direction[i];
        vec3 h = normalize(l + v);
        float n_dot_l = clamp(dot(n, l), 0.001, 1.0);
        float n_dot_h = clamp(dot(n, h), 0.0, 1.0);
        float v_dot_h = clamp(dot(v, h), 0.0, 1.0);
        vec3 fresnel = f0 + (1.0 - f0) * pow(1.0 - v_dot_h, 5.0);
        float geometry = n_dot_v / (n_dot_v * (1.0 - k) + k) * n_dot_l / (n_dot_l * (1.0 - k) + k);
        float d = n_dot_h * n_dot_h * (alpha2 - 1.0) + 1.0;
        float distribution = alpha2 / (PI * d * d);
        vec3 diffuse = (1.0 - fresnel) * diffuse_color / PI;
        vec3 specular = fresnel * geometry * distribution / (4.0 * n_dot_l * n_dot_v + 0.001);
        color += n_dot_l * light_radiance[i] * (diffuse + specular);
    }
    color += ambient * base.rgb;
    color *= v_color.rgb;            // vertex colours tint the lit surface, highlights included
    frag_color = clamp(vec4(pow(color, vec3(1.0 / 2.2)), base.a * v_color.a), 0.0, 1.0);
}
"""




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
    """Anything `mop.export.parse_background` takes -> (r, g, b, a) in 0..1 (transparent:
    alpha 0)."""
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
    """Write positions and normals into the interleaved float32 vertex buffer (V, _STRIDE)."""
    for i in range(x.shape[0]):
        for k in range(3):
            buffer[i, k] = x[i, k]
            buffer[i, 3 + k] = normals[i, k]


class _Item:
    """One mesh in the scene: its buffers on the CPU (reused every frame) and on the GPU."""

    def __init__(self, source, faces, colors, look: Look, name: str):
        self.source = source
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.look = look
        self.name = name
        positions = self._positions()
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or (
                self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(positions))):
            raise ValueError(f"{name}: faces must be (F, 3) indices into {len(positions)} "
                             f"vertices, got shape {self.faces.shape}")
        self.normals = np.empty_like(positions)
        vertex_normals(positions, self.faces, self.normals)
        self.buffer = np.ones((len(positions), _STRIDE), dtype=np.float32)
        self.buffer[:, :3] = positions
        self.buffer[:, 3:6] = self.normals
        if colors is not None and look.use_vertex_colors:
            colors = np.asarray(colors)
            if colors.shape != (len(positions), 4) and colors.shape != (len(positions), 3):
                raise ValueError(f"colors must have shape ({len(positions)}, 3|4), got "
                                 f"{colors.shape}")
            rgba = np.ones((len(positions), 4), dtype=np.float32)
            scale = 255.0 if colors.dtype == np.uint8 else 1.0
            rgba[:, :colors.shape[1]] = colors / scale
            # the shader works in linear light: undo the colours' sRGB encoding
            rgba[:, :3] = np.where(rgba[:, :3] <= 0.04045, rgba[:, :3] / 12.92,
                                   ((rgba[:, :3] + 0.055) / 1.055) ** 2.4)
            self.buffer[:, 6:10] = rgba
        self.rest_bounds = np.stack([positions.min(0), positions.max(0)])
        self.vbo = self.ibo = self.vao = None

    def upload(self, context, program) -> None:
        self.vbo = context.buffer(self.buffer)
        self.ibo = context.buffer(self.faces.astype(np.uint32))
        self.vao = context.vertex_array(
            program, [(self.vbo, "3f 3f 4f", "in_position", "in_normal", "in_color")],
            index_buffer=self.ibo, index_element_size=4)

    def release(self) -> None:
        for resource in (self.vao, self.vbo, self.ibo):
            if resource is not None:
                resource.release()
        self.vbo = self.ibo = self.vao = None

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


def _perspective(yfov: float, aspect: float, znear: float, zfar: float) -> np.ndarray:
    """OpenGL projection (4, 4) of a perspective camera (the glTF 2.0 camera model)."""
    t = np.tan(yfov / 2.0)
    projection = np.zeros((4, 4))
    projection[0, 0] = 1.0 / (aspect * t)
    projection[1, 1] = 1.0 / t
    projection[2, 2] = (zfar + znear) / (znear - zfar)
    projection[2, 3] = 2.0 * zfar * znear / (znear - zfar)
    projection[3, 2] = -1.0
    return projection


def _open_context():
    try:
        return moderngl.create_context(standalone=True, backend="egl", require=330)
    except Exception as error:
        raise RuntimeError(
            f"3D rendering could not open an offscreen OpenGL context through EGL ({error}); "
            f"on Debian: apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri") from None


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera pose (4, 4): camera at eye looking at target, +y up (OpenGL looks along -z)."""
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
    """A scene built once; meshes' vertices change per frame.

    size : (width, height) [px]; camera : a CAMERAS name or a (4, 4) camera pose;
    background : see `parse_background`; antialias : 4x multisampling (slower on software
    rasterisers); yfov : vertical field of view [rad];
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
        self._ambient = (0.28, 0.28, 0.3)
        self._items: list[_Item] = []
        self._framed = False
        self._lock = threading.Lock()
        self._context = _open_context()
        with self._context:
            self._program = self._context.program(vertex_shader=_VERTEX_SHADER,
                                                  fragment_shader=_FRAGMENT_SHADER)
            self._program["ambient"].value = self._ambient
            self._target = self._context.framebuffer(
                color_attachments=[self._context.renderbuffer((width, height), 4)],
                depth_attachment=self._context.depth_renderbuffer((width, height)))
            self._drawn = self._target
            if antialias:
                samples = min(4, self._context.max_samples)
                self._drawn = self._context.framebuffer(
                    color_attachments=[self._context.renderbuffer((width, height), 4,
                                                                  samples=samples)],
                    depth_attachment=self._context.depth_renderbuffer((width, height),
                                                                      samples=samples))
        self._pixels = np.empty((height, width, 4), np.uint8)

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
        with self._lock, self._context:
            entry.upload(self._context, self._program)
        self._items.append(entry)
        if not self._framed:
            self.frame()
        return len(self._items) - 1

    def frame(self, bounds: np.ndarray | None = None, *, margin: float = 1.15) -> None:
        """Point the camera (and the lights) at bounds (2, 3) [m], default all meshes at rest."""
        self._check_open()
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
        projection = _perspective(self._yfov, aspect, distance * 0.05, distance * 4)
        view_projection = projection @ np.linalg.inv(pose)
        # a directional light shines along -z of its pose: the surface sees it along +z
        if self._lights == "flat":
            lights = [(pose[:3, 2], (3.0, 3.0, 3.0))]
        else:
            lights = []
            for offset, intensity in (((0.5, 0.6, 0.0), 3.2), ((-0.7, 0.1, 0.0), 1.2),
                                      ((0.0, 0.5, -1.6), 2.0)):
                eye = pose[:3, 3] + pose[:3, :3] @ (np.asarray(offset) * distance)
                radiance = tuple(intensity * c for c in (1.0, 0.97, 0.92))
                lights.append((_look_at(eye, centre)[:3, 2], radiance))
        directions = np.zeros((_MAX_LIGHTS, 3), np.float32)
        radiances = np.zeros((_MAX_LIGHTS, 3), np.float32)
        for index, (direction, radiance) in enumerate(lights):
            directions[index] = direction
            radiances[index] = radiance
        with self._lock, self._context:
            program = self._program
            # column-major, as GLSL reads matrices
            program["view_projection"].write(view_projection.T.astype(np.float32).tobytes())
            program["camera_position"].value = tuple(float(c) for c in pose[:3, 3])
            program["light_count"].value = len(lights)
            program["light_direction"].write(directions.tobytes())
            program["light_radiance"].write(radiances.tobytes())
        self._framed = True

    # --- per frame -----------------------------------------------------------------------------
    def update(self, handle: int | None = None, vertices: np.ndarray | None = None) -> None:
        """Take new vertex positions: of one handle (vertices (V, 3) [m], or the puppet's
        surface() when None), or of every puppet when handle is None."""
        self._check_open()
        items = self._items if handle is None else [self._items[handle]]
        for item in items:
            item.refresh(vertices if handle is not None else None)
        with self._lock, self._context:
            for item in items:
                item.vbo.write(item.buffer)

    def render(self) -> np.ndarray:
        """The current frame, (H, W, 4) uint8 RGBA with straight alpha."""
        self._check_open()
        if not self._items:
            raise ValueError("the scene is empty: add a mesh before rendering")
        context, program = self._context, self._program
        with self._lock, context:
            self._drawn.use()
            self._drawn.clear(*self.background)
            context.enable(moderngl.DEPTH_TEST)
            for item in self._items:
                if item.look.double_sided:
                    context.disable(moderngl.CULL_FACE)
                else:
                    context.enable(moderngl.CULL_FACE)
                program["base_color_factor"].value = (*item.look.base_color, 1.0)
                program["metallic"].value = float(item.look.metallic)
                program["roughness"].value = float(item.look.roughness)
                item.vao.render(moderngl.TRIANGLES)
            if self._drawn is not self._target:  # resolve the multisampled frame
                context.copy_framebuffer(self._target, self._drawn)
            self._target.read_into(self._pixels, components=4, alignment=1)
        return self._pixels[::-1].copy()   # OpenGL's rows run bottom-up

    # --- life cycle ----------------------------------------------------------------------------
    def release(self) -> None:
        """Let another thread draw this scene next. Nothing to do: the scene's context is
        current only inside its own calls, which leave no context current behind them."""

    def close(self) -> None:
        """Free the OpenGL context and buffers (idempotent)."""
        context, self._context = getattr(self, "_context", None), None
        if context is None:
            return
        with self._lock:
            with context:
                for item in self._items:
                    item.release()
                for resource in {id(f): f for f in (self._drawn, self._target)}.values():
                    resource.release()
                self._program.release()
            context.release()

    @property
    def closed(self) -> bool:
        return self._context is None

    def _check_open(self) -> None:
        if self._context is None:
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
