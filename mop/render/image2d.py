"""Texture-mapped rendering of deformed 2D meshes (image puppets) on the CPU.

Each triangle's piece of the picture follows its triangle: for every output pixel a triangle
covers, the affine map from the deformed triangle back to its rest triangle gives the texture
position, sampled bilinearly from a premultiplied copy of the picture (so transparent texels
never bleed colour into the edge). The picture's feathered alpha gives the clean silhouette.

Why a numba scanline rasteriser rather than OpenGL: measured in benchmarks/image_puppet.py on a
machine without a GPU, pyrender/EGL on llvmpipe spends more per frame on its fixed costs (and
the read-back) than this kernel spends drawing a whole 512x512 puppet; the figures are in
docs/benchmarks.md (Image puppets).

Coverage rule: pixel centres are at integer (x = column, y = row). Every edge is evaluated in
one canonical direction (lower vertex index first), and a pixel exactly on an edge goes to one
side only, so the triangles of a mesh that does not fold cover every pixel exactly once: no gaps
and no double blending along shared edges.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from mop.export import parse_background

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@njit(**_JIT)
def premultiply(rgba, out):
    """out (H, W, 4) uint8 = rgba (H, W, 4) uint8 straight alpha with colour scaled by alpha."""
    height, width = rgba.shape[0], rgba.shape[1]
    for r in range(height):
        for c in range(width):
            a = np.int32(rgba[r, c, 3])
            for k in range(3):
                out[r, c, k] = (np.int32(rgba[r, c, k]) * a + 127) // 255
            out[r, c, 3] = a


@njit(**_JIT)
def unpremultiply(image, bounds):
    """In place: premultiplied (H, W, 4) uint8 -> straight alpha, within bounds
    (row0, row1, col0, col1), inclusive, as left by `rasterise`."""
    for r in range(bounds[0], bounds[1] + 1):
        for c in range(bounds[2], bounds[3] + 1):
            a = np.int32(image[r, c, 3])
            if 0 < a < 255:
                for k in range(3):
                    value = (np.int32(image[r, c, k]) * 255 + a // 2) // a
                    image[r, c, k] = min(value, 255)


@njit(**_JIT)
def _edge_bound(x0, y0, x1, y1, side, y, bounds):
    """Tighten bounds[0] (lowest column) / bounds[1] (highest column) on row y by one edge.

    The edge (x0, y0) -> (x1, y1) is in canonical order; side = +1 / -1 is the sign of the
    canonical edge function E(x, y) = (x - x0)(y1 - y0) - (y - y0)(x1 - x0) inside the
    triangle. A pixel with E == 0 belongs to the triangle with side = +1 only.
    Returns False if the row is entirely outside (horizontal edge)."""
    dy = y1 - y0
    if dy == 0.0:
        value = -(y - y0) * (x1 - x0)
        if value == 0.0:
            return side > 0
        return value * side > 0.0
    crossing = x0 + (y - y0) * (x1 - x0) / dy
    if side * dy > 0.0:
        # inside for x > crossing (and x == crossing if side > 0)
        low = np.ceil(crossing) if side > 0 else np.floor(crossing) + 1.0
        if low > bounds[0]:
            bounds[0] = low
    else:
        high = np.floor(crossing) if side > 0 else np.ceil(crossing) - 1.0
        if high < bounds[1]:
            bounds[1] = high
    return True


@njit(**_JIT)
def _lerp_packed(a, b, w):
    """Blend two packed RGBA texels (uint32 as int64) with weight w in 0..256 on b."""
    # + 0x00800080 rounds each channel's >> 8 instead of truncating
    rb = (((a & 0x00FF00FF) * (256 - w) + (b & 0x00FF00FF) * w + 0x00800080) >> 8) & 0x00FF00FF
    ga = ((((a >> 8) & 0x00FF00FF) * (256 - w) + ((b >> 8) & 0x00FF00FF) * w + 0x00800080)
          >> 8) & 0x00FF00FF
    return rb | (ga << 8)


@njit(**_JIT)
def _sample(texture, s_fixed, t_fixed):
    """Bilinear sample of texture (Ht, Wt) uint32 premultiplied RGBA at a 16.16 fixed-point
    position already clamped to the texture: the packed texel as int64."""
    tex_h, tex_w = texture.shape[0], texture.shape[1]
    i0 = s_fixed >> 16
    j0 = t_fixed >> 16
    wx = ((s_fixed & 0xFFFF) + 128) >> 8
    wy = ((t_fixed & 0xFFFF) + 128) >> 8
    i1 = min(i0 + 1, tex_w - 1)
    j1 = min(j0 + 1, tex_h - 1)
    top = _lerp_packed(np.int64(texture[j0, i0]), np.int64(texture[j0, i1]), wx)
    bottom = _lerp_packed(np.int64(texture[j1, i0]), np.int64(texture[j1, i1]), wx)
    return _lerp_packed(top, bottom, wy)


@njit(**_JIT)
def _over(dst, src, alpha):
    """Premultiplied over of packed texels: dst * (255 - alpha) / 255 + src, per packed channel
    pair (alpha = src's, 0 < alpha < 255)."""
    keep = 255 - alpha
    keep += keep >> 7  # 0..255 -> 0..256
    rb = ((((dst & 0x00FF00FF) * keep + 0x00800080) >> 8) & 0x00FF00FF) + (src & 0x00FF00FF)
    ga = (((((dst >> 8) & 0x00FF00FF) * keep + 0x00800080) >> 8) & 0x00FF00FF) + (
        (src >> 8) & 0x00FF00FF)
    return rb | (ga << 8)


@njit(**_JIT)
def _draw_span(out, texture, r, c_low, c_high, s_fixed, t_fixed, s_step, t_step):
    """Draw row r of `out` from column c_low to c_high (inclusive), the texture position
    stepping from (s_fixed, t_fixed) by (s_step, t_step) per column, in 16.16 fixed point and
    clamped so edge pixels never read outside the texture."""
    s_limit = np.int64(texture.shape[1] - 1) << 16
    t_limit = np.int64(texture.shape[0] - 1) << 16
    for c in range(c_low, c_high + 1):
        src = _sample(texture, min(max(s_fixed, 0), s_limit), min(max(t_fixed, 0), t_limit))
        s_fixed += s_step
        t_fixed += t_step
        alpha = src >> 24
        if alpha == 0:
            continue
        if alpha == 255:
            out[r, c] = np.uint32(src)
        else:
            out[r, c] = np.uint32(_over(np.int64(out[r, c]), src, alpha))


@njit(**_JIT)
def _canonical_edges(screen_xy, v0, v1, v2, ea, eb, es):
    """The triangle's edges in canonical order (lower vertex index first) into ea, eb (3,), and
    into es (3,) the side (+1 / -1) of each edge function the triangle lies on."""
    for k in range(3):
        a = v0 if k == 0 else (v1 if k == 1 else v2)
        b = v1 if k == 0 else (v2 if k == 1 else v0)
        o = v2 if k == 0 else (v0 if k == 1 else v1)
        if a > b:
            a, b = b, a
        ax, ay = screen_xy[a, 0], screen_xy[a, 1]
        bx, by = screen_xy[b, 0], screen_xy[b, 1]
        value = (screen_xy[o, 0] - ax) * (by - ay) - (screen_xy[o, 1] - ay) * (bx - ax)
        ea[k] = a
        eb[k] = b
        es[k] = 1.0 if value > 0.0 else -1.0


@njit(**_JIT)
def _row_bounds(screen_xy, ea, eb, es, y, bounds):
    """Narrow bounds (2,) [lowest, highest column] to the triangle's pixels on row y; False if
    the row has none."""
    for k in range(3):
        a = ea[k]
        b = eb[k]
        if not _edge_bound(screen_xy[a, 0], screen_xy[a, 1], screen_xy[b, 0], screen_xy[b, 1],
                           es[k], y, bounds):
            return False
    return bounds[0] <= bounds[1]


@njit(**_JIT)
def _grow_box(drawn, r, c_low, c_high):
    drawn[0] = min(drawn[0], r)
    drawn[1] = max(drawn[1], r)
    drawn[2] = min(drawn[2], c_low)
    drawn[3] = max(drawn[3], c_high)


@njit(**_JIT)
def rasterise(out, texture, texture_xy, screen_xy, triangles, drawn):
    """Draw textured triangles into `out` with the premultiplied "over" operator.

    out : (H, W) uint32 premultiplied RGBA (the (H, W, 4) uint8 frame viewed as uint32, so
        byte order R, G, B, A), drawn over in place
    texture : (Ht, Wt) uint32 premultiplied RGBA, same packing
    texture_xy : (N, 2) float [texels] rest vertex positions in the texture
    screen_xy : (N, 2) float [px] deformed vertex positions in `out`
    triangles : (F, 3) int
    drawn : (4,) int64, updated to the (row0, row1, col0, col1) box of drawn pixels

    Bilinear sampling in 8-bit fixed point on two channels per multiply (R|B and G|A): exact
    at texel centres, within 1/255 elsewhere.
    """
    height, width = out.shape[0], out.shape[1]
    bounds = np.empty(2)
    ea = np.empty(3, np.int64)
    eb = np.empty(3, np.int64)
    es = np.empty(3)
    for f in range(triangles.shape[0]):
        v0 = triangles[f, 0]
        v1 = triangles[f, 1]
        v2 = triangles[f, 2]
        x0, y0 = screen_xy[v0, 0], screen_xy[v0, 1]
        x1, y1 = screen_xy[v1, 0], screen_xy[v1, 1]
        x2, y2 = screen_xy[v2, 0], screen_xy[v2, 1]
        e1x, e1y = x1 - x0, y1 - y0
        e2x, e2y = x2 - x0, y2 - y0
        det = e1x * e2y - e2x * e1y
        if det == 0.0 or not np.isfinite(det):
            continue
        row_low = max(0, int(np.ceil(min(y0, min(y1, y2)))))
        row_high = min(height - 1, int(np.floor(max(y0, max(y1, y2)))))
        col_min = max(0.0, np.ceil(min(x0, min(x1, x2))))
        col_max = min(width - 1.0, np.floor(max(x0, max(x1, x2))))
        if row_low > row_high or col_min > col_max:
            continue
        # screen -> texture affine map, from the barycentric coordinates
        s0, t0 = texture_xy[v0, 0], texture_xy[v0, 1]
        ds1, dt1 = texture_xy[v1, 0] - s0, texture_xy[v1, 1] - t0
        ds2, dt2 = texture_xy[v2, 0] - s0, texture_xy[v2, 1] - t0
        inv = 1.0 / det
        s_dx = (ds1 * e2y - ds2 * e1y) * inv
        s_dy = (-ds1 * e2x + ds2 * e1x) * inv
        t_dx = (dt1 * e2y - dt2 * e1y) * inv
        t_dy = (-dt1 * e2x + dt2 * e1x) * inv
        _canonical_edges(screen_xy, v0, v1, v2, ea, eb, es)
        for r in range(row_low, row_high + 1):
            y = float(r)
            bounds[0] = col_min
            bounds[1] = col_max
            if not _row_bounds(screen_xy, ea, eb, es, y, bounds):
                continue
            c_low = int(bounds[0])
            c_high = int(bounds[1])
            _grow_box(drawn, r, c_low, c_high)
            # the texture position at the span's first pixel, in 16.16 fixed point
            s = s0 + s_dx * (c_low - x0) + s_dy * (y - y0)
            t = t0 + t_dx * (c_low - x0) + t_dy * (y - y0)
            _draw_span(out, texture, r, c_low, c_high, np.int64(s * 65536.0 + 0.5),
                       np.int64(t * 65536.0 + 0.5), np.int64(s_dx * 65536.0 + 0.5),
                       np.int64(t_dx * 65536.0 + 0.5))


def _packed(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 C-contiguous -> (H, W) uint32 view of the same memory."""
    return rgba.view(np.uint32).reshape(rgba.shape[:2])


class ImageRenderer:
    """Draws one picture on a deformable 2D mesh, frame after frame.

    texture : (Ht, Wt, 4) uint8 RGBA, straight alpha (the puppet's cut-out picture)
    texture_xy : (N, 2) float [texels] rest vertex positions in the picture (pixel centres at
        integers); for an image puppet these are its rest vertices
    triangles : (F, 3) int
    size : (width, height) [px] of the frames
    background : "transparent" | "#rrggbb" | "chroma" | (r, g, b)

    `render(vertices)` returns a new (height, width, 4) uint8 RGBA frame (straight alpha; alpha
    255 over a colour background); `render_into(vertices, frame)` reuses a frame buffer.
    """

    def __init__(self, texture: np.ndarray, texture_xy: np.ndarray, triangles: np.ndarray, *,
                 size: tuple[int, int], background="transparent"):
        texture = np.asarray(texture)
        if texture.dtype != np.uint8 or texture.ndim != 3 or texture.shape[2] != 4:
            raise ValueError(f"texture must be (H, W, 4) uint8 RGBA, got {texture.shape} "
                             f"{texture.dtype}")
        self.texture_xy = np.ascontiguousarray(texture_xy, dtype=np.float64)
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int64)
        if self.texture_xy.ndim != 2 or self.texture_xy.shape[1] != 2:
            raise ValueError(f"texture_xy must be (N, 2), got {self.texture_xy.shape}")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3:
            raise ValueError(f"triangles must be (F, 3), got {self.triangles.shape}")
        if self.triangles.size and (self.triangles.min() < 0
                                    or self.triangles.max() >= len(self.texture_xy)):
            raise ValueError(f"triangles index vertices outside [0, {len(self.texture_xy)})")
        self.width, self.height = (int(v) for v in size)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"size must be (width, height) >= 1, got {size}")
        self.colour = parse_background(background)
        premultiplied = np.empty_like(texture)
        premultiply(np.ascontiguousarray(texture), premultiplied)
        self.texture = _packed(premultiplied)
        self._blank = np.zeros((self.height, self.width, 4), np.uint8)
        if self.colour is not None:
            self._blank[:, :, :3] = self.colour
            self._blank[:, :, 3] = 255
        self._drawn = np.empty(4, np.int64)

    @property
    def vertex_count(self) -> int:
        return len(self.texture_xy)

    def render(self, vertices: np.ndarray) -> np.ndarray:
        """(height, width, 4) uint8 RGBA of the mesh at vertices (N, 2) float [px]."""
        frame = np.empty_like(self._blank)
        return self.render_into(vertices, frame)

    def render_into(self, vertices: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Like `render`, into frame (height, width, 4) uint8 (overwritten); returns frame."""
        vertices = np.asarray(vertices, dtype=np.float64)
        if vertices.shape != self.texture_xy.shape:
            raise ValueError(f"vertices must have shape {self.texture_xy.shape}, got "
                             f"{vertices.shape}")
        if frame.shape != self._blank.shape or frame.dtype != np.uint8:
            raise ValueError(f"frame must be {self._blank.shape} uint8, got {frame.shape} "
                             f"{frame.dtype}")
        np.copyto(frame, self._blank)
        drawn = self._drawn
        drawn[0], drawn[1], drawn[2], drawn[3] = self.height, -1, self.width, -1
        rasterise(_packed(frame), self.texture, self.texture_xy, np.ascontiguousarray(vertices),
                  self.triangles, drawn)
        if self.colour is None and drawn[1] >= 0:
            unpremultiply(frame, drawn)
        return frame


def draw_mesh_preview(image: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, *,
                      pins=(), contour: np.ndarray | None = None,
                      background="#ffffff", dim: float = 0.35) -> np.ndarray:
    """A picture of a built mesh: the (dimmed) cut-out, the triangles, the contour and the pins.

    image : (H, W, 4) uint8 RGBA cut-out; vertices : (N, 2) float [px]; triangles : (F, 3) int;
    pins : iterable of (name, (x, y), fixed) with (x, y) the pinned vertex [px];
    contour : (K, 2) float [px] or None. Returns (H, W, 3) uint8 RGB.
    Driven pins are drawn as orange discs, anchors as blue squares, the contour in blue."""
    import cv2
    from mop.export import over_colour
    rgb = over_colour(image, background).astype(np.float32)
    colour = np.asarray(parse_background(background) or (255, 255, 255), np.float32)
    canvas = np.ascontiguousarray((rgb * (1.0 - dim) + colour * dim).astype(np.uint8))
    shift = 4
    points = np.round(np.asarray(vertices) * (1 << shift)).astype(np.int32)
    height, width = canvas.shape[:2]
    thin = max(1, round(max(height, width) / 700))
    polygons = [points[t].reshape(-1, 1, 2) for t in np.asarray(triangles)]
    cv2.polylines(canvas, polygons, True, (40, 40, 40), thin, cv2.LINE_AA, shift)
    if contour is not None and len(contour):
        outline = np.round(np.asarray(contour) * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(canvas, [outline], True, (30, 110, 230), thin + 1, cv2.LINE_AA, shift)
    radius = max(5, round(max(height, width) / 70))
    for name, xy, fixed in pins:
        x, y = (int(round(v)) for v in xy)
        if fixed:
            cv2.rectangle(canvas, (x - radius, y - radius), (x + radius, y + radius),
                          (20, 70, 200), -1, cv2.LINE_AA)
        else:
            cv2.circle(canvas, (x, y), radius, (240, 120, 20), -1, cv2.LINE_AA)
        cv2.circle(canvas, (x, y), radius + 1, (255, 255, 255), thin, cv2.LINE_AA)
        scale = max(0.4, max(height, width) / 1300)
        (text_width, text_height), _ = cv2.getTextSize(name, cv2.FONT_HERSHEY_SIMPLEX, scale, thin)
        left = x + radius + 3
        if left + text_width >= width:   # keep the label inside the picture
            left = max(0, x - radius - 3 - text_width)
        top = max(text_height + 2, y - radius)
        for colour, weight in (((255, 255, 255), 3 * thin), ((20, 20, 20), thin)):
            cv2.putText(canvas, name, (left, top), cv2.FONT_HERSHEY_SIMPLEX, scale, colour,
                        weight, cv2.LINE_AA)
    return canvas


def puppet_preview(puppet, *, background="#ffffff") -> np.ndarray:
    """`draw_mesh_preview` of an ImagePuppet with its pins: (H, W, 3) uint8 RGB."""
    pins = [(pin.name, puppet.vertices[pin.index], pin.fixed) for pin in puppet.pins.values()]
    return draw_mesh_preview(puppet.image, puppet.vertices, puppet.triangles, pins=pins,
                             contour=puppet.contour, background=background)
