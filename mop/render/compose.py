"""Composing several characters into one frame, and a plain mesh renderer to fall back on.

Every character renders into its own RGBA layer (straight alpha, uint8); `Stage` places the layers
into one frame over a colour, a chroma-key colour or transparency, back to front in session order.
`blend_over` is mop's one compositor: `mop.export.compose_layers` and `over_colour` use it too.
Colours are parsed by `mop.export.parse_background`.
"""
from __future__ import annotations

import numpy as np
from numba import njit

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


def blend_over(canvas: np.ndarray, layer: np.ndarray, x0: int, y0: int, *,
               opaque: bool = False) -> None:
    """Alpha-composite `layer` over `canvas` in place, top-left corner at (x0, y0) [px].

    canvas : (H, W, 4) uint8 RGBA, straight alpha; layer : (h, w, 4) uint8 RGBA, straight alpha.
    Parts of the layer outside the canvas are clipped. `opaque=True` promises the canvas is
    opaque everywhere (a colour background), which allows integer arithmetic. Compiled, pixel by
    pixel, with nothing allocated; a layer's transparent pixels (most of a character's layer)
    cost one comparison each."""
    if canvas.dtype != np.uint8 or layer.dtype != np.uint8:
        raise ValueError(f"canvas and layer must be uint8, got {canvas.dtype} and {layer.dtype}")
    if canvas.ndim != 3 or canvas.shape[2] != 4 or layer.ndim != 3 or layer.shape[2] != 4:
        raise ValueError(f"canvas and layer must be (H, W, 4) RGBA, got {canvas.shape} and "
                         f"{layer.shape}")
    height, width = canvas.shape[:2]
    h, w = layer.shape[:2]
    xa, ya = max(x0, 0), max(y0, 0)
    xb, yb = min(x0 + w, width), min(y0 + h, height)
    if xa >= xb or ya >= yb:
        return
    src = layer[ya - y0:yb - y0, xa - x0:xb - x0]
    dst = canvas[ya:yb, xa:xb]
    if opaque:
        _over_opaque(dst, src)
    else:
        _over_straight(dst, src)


@njit(**_JIT)
def _over_opaque(dst, src):
    """dst.rgb = (src.rgb a + dst.rgb (255 - a) + 127) // 255 over an opaque dst, a = src
    alpha: exact at a = 0 (dst kept) and a = 255 (src copied)."""
    for y in range(src.shape[0]):
        for x in range(src.shape[1]):
            a = np.uint16(src[y, x, 3])
            if a == 0:
                continue
            if a == 255:
                for c in range(3):
                    dst[y, x, c] = src[y, x, c]
                continue
            for c in range(3):
                mixed = np.uint16(src[y, x, c]) * a + np.uint16(dst[y, x, c]) * (255 - a) + 127
                dst[y, x, c] = mixed // 255


@njit(**_JIT)
def _over_straight(dst, src):
    """Porter-Duff 'over' with straight alpha in float32 (fully transparent results are
    (0, 0, 0, 0))."""
    scale = np.float32(1.0 / 255.0)
    one = np.float32(1.0)
    for y in range(src.shape[0]):
        for x in range(src.shape[1]):
            if src[y, x, 3] == 0:  # dst kept; a fully transparent result is all zeros
                if dst[y, x, 3] == 0:
                    for c in range(3):
                        dst[y, x, c] = 0
                continue
            if src[y, x, 3] == 255:
                for c in range(4):
                    dst[y, x, c] = src[y, x, c]
                continue
            sa = np.float32(src[y, x, 3]) * scale
            da = np.float32(dst[y, x, 3]) * scale
            keep = da * (one - sa)
            out = sa + keep
            safe = out if out > 0 else one
            for c in range(3):
                colour = (np.float32(src[y, x, c]) * scale * sa
                          + np.float32(dst[y, x, c]) * scale * keep)
                value = colour / safe * np.float32(255.0) + np.float32(0.5)
                dst[y, x, c] = np.uint8(min(max(value, np.float32(0.0)), np.float32(255.0)))
            value = out * np.float32(255.0) + np.float32(0.5)
            dst[y, x, 3] = np.uint8(min(max(value, np.float32(0.0)), np.float32(255.0)))


class Stage:
    """The frame: a background and the characters' layers placed on it.

    size : (width, height) [px]; background : (r, g, b) or None for transparent."""

    def __init__(self, size: tuple[int, int], background: tuple[int, int, int] | None):
        self.width, self.height = int(size[0]), int(size[1])
        self.background = background
        self.frame = np.zeros((self.height, self.width, 4), dtype=np.uint8)
        self._blank = np.zeros_like(self.frame)  # the cleared frame, copied in by clear()
        if background is not None:
            self._blank[..., :3] = background
            self._blank[..., 3] = 255

    def clear(self) -> np.ndarray:
        np.copyto(self.frame, self._blank)
        return self.frame

    def place(self, layer: np.ndarray, centre: tuple[float, float]) -> None:
        """Draw a layer centred at `centre` = (x, y) as fractions of the frame's width, height."""
        h, w = layer.shape[:2]
        x0 = int(round(centre[0] * self.width - w / 2))
        y0 = int(round(centre[1] * self.height - h / 2))
        blend_over(self.frame, layer, x0, y0, opaque=self.background is not None)


class MeshLayerRenderer:
    """Flat-shaded orthographic drawing of any puppet's `surface()` and `faces`.

    The fallback when a puppet kind has no renderer of its own (and the renderer of test
    stand-ins). 2D surfaces are in image coordinates (y down); 3D surfaces are viewed along -z
    with y up. The rest surface's bounding box, plus `margin`, fills the layer.

    rest : (V, 2|3) float, faces : (F, 3) int, height : layer height [px]."""

    def __init__(self, rest: np.ndarray, faces: np.ndarray, *, height: int,
                 colour: tuple[int, int, int] = (200, 140, 90), margin: float = 0.25):
        import cv2  # noqa: F401  (checked here so a missing OpenCV fails at build, not mid-show)
        rest = np.asarray(rest, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.dim = rest.shape[1]
        self.colour = np.asarray(colour, dtype=np.float64)
        xy = self._project(rest)
        low, high = xy.min(0), xy.max(0)
        extent = (high - low) * (1.0 + 2.0 * margin)
        extent = np.maximum(extent, 1e-9)
        self.scale = height / extent[1]
        self.height = int(height)
        self.width = max(2, int(round(extent[0] * self.scale)))
        self.offset = (low + high) / 2.0
        self.layer = np.zeros((self.height, self.width, 4), dtype=np.uint8)

    def _project(self, vertices: np.ndarray) -> np.ndarray:
        if self.dim == 2:
            return vertices[:, :2]
        return np.stack([vertices[:, 0], -vertices[:, 1]], axis=1)

    def render(self, puppet) -> np.ndarray:
        """(h, w, 4) uint8 RGBA layer of the puppet's surface now."""
        import cv2
        vertices = np.asarray(puppet.surface(), dtype=np.float64)
        xy = (self._project(vertices) - self.offset) * self.scale
        xy += (self.width / 2.0, self.height / 2.0)
        pixels = np.round(xy * 16).astype(np.int32)  # 4 bits of sub-pixel precision
        self.layer[...] = 0
        triangles = pixels[self.faces]
        if self.dim == 3:
            a, b, c = (vertices[self.faces[:, k]] for k in range(3))
            normal = np.cross(b - a, c - a)
            length = np.linalg.norm(normal, axis=1)
            shade = np.abs(normal[:, 2]) / np.where(length > 0, length, 1.0)
            order = np.argsort(vertices[self.faces].mean(1)[:, 2], kind="stable")
        else:
            shade = np.ones(len(self.faces))
            order = np.arange(len(self.faces))
        shade = 0.35 + 0.65 * shade
        for face in order:
            r, g, b = self.colour * shade[face]
            cv2.fillConvexPoly(self.layer, triangles[face], (r, g, b, 255), lineType=cv2.LINE_AA,
                               shift=4)
        return self.layer

    def close(self) -> None:
        pass
