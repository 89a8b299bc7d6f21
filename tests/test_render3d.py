"""The offscreen 3D renderer: backgrounds, RGBA output, in-place vertex updates that match a
scene rebuilt from scratch, normals against a NumPy reference, and closing."""
import numpy as np
import pytest

pytest.importorskip("moderngl")
trimesh = pytest.importorskip("trimesh")

from mop.render.scene3d import Scene3D, parse_background, vertex_normals  # noqa: E402

SIZE = (160, 120)


class _Blob:
    """A minimal puppet: surface() and faces, like every puppet kind."""

    def __init__(self):
        sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
        self.rest = np.array(sphere.vertices)
        self.faces = np.array(sphere.faces)
        self.x = self.rest.copy()
        self.vertex_colors = np.tile(np.array([[200, 60, 60, 255]], dtype=np.uint8),
                                     (len(self.rest), 1))

    def surface(self):
        return self.x


def _alpha_centre(rgba):
    alpha = rgba[..., 3] > 0
    rows, cols = np.nonzero(alpha)
    return cols.mean(), rows.mean(), alpha.mean()


def test_transparent_background_and_opaque_puppet():
    blob = _Blob()
    with Scene3D(size=SIZE, camera="front") as scene:
        scene.add(blob)
        rgba = scene.render()
    assert rgba.shape == (SIZE[1], SIZE[0], 4) and rgba.dtype == np.uint8
    assert rgba[0, 0, 3] == 0 and rgba[-1, -1, 3] == 0
    centre = rgba[SIZE[1] // 2, SIZE[0] // 2]
    assert centre[3] == 255
    assert centre[0] > centre[1] and centre[0] > centre[2]  # the red vertex colour shows
    cx, cy, share = _alpha_centre(rgba)
    assert abs(cx - SIZE[0] / 2) < 3 and abs(cy - SIZE[1] / 2) < 3 and 0.05 < share < 0.8


def test_chroma_key_background():
    with Scene3D(size=SIZE, background="chroma") as scene:
        scene.add(_Blob())
        rgba = scene.render()
    np.testing.assert_array_equal(rgba[0, 0], [0, 177, 64, 255])
    assert np.all(rgba[..., 3] == 255)


def test_updating_vertices_matches_a_rebuilt_scene():
    blob = _Blob()
    with Scene3D(size=SIZE, camera="front") as scene:
        scene.add(blob)
        first = scene.render()
        blob.x = blob.rest * [1.0, 0.6, 1.0] + [0.03, 0.0, 0.0]  # squash and move right
        scene.update()
        moved = scene.render()
    x_first, _, share_first = _alpha_centre(first)
    x_moved, _, share_moved = _alpha_centre(moved)
    assert x_moved > x_first + 5 and share_moved < share_first
    # the same geometry in a scene built from scratch with the same camera renders the same
    fresh_blob = _Blob()
    with Scene3D(size=SIZE, camera="front") as fresh:
        fresh.add(fresh_blob)
        fresh_blob.x = blob.x.copy()
        fresh.update()
        rebuilt = fresh.render()
    assert np.abs(rebuilt.astype(int) - moved.astype(int)).max() <= 2


def test_vertex_normals_match_numpy_reference(rng):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    x = sphere.vertices + rng.normal(scale=0.02, size=sphere.vertices.shape)
    out = np.empty_like(x)
    vertex_normals(x, np.asarray(sphere.faces), out)
    a, b, c = (x[sphere.faces[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)
    reference = np.zeros_like(x)
    for corner in range(3):
        np.add.at(reference, sphere.faces[:, corner], face)
    reference /= np.linalg.norm(reference, axis=1, keepdims=True)
    np.testing.assert_allclose(out, reference, atol=1e-12)


def test_closed_scene_refuses_to_render_and_bad_options_fail():
    scene = Scene3D(size=SIZE)
    scene.add(_Blob())
    scene.close()
    scene.close()  # idempotent
    assert scene.closed
    with pytest.raises(ValueError, match="closed"):
        scene.render()
    with pytest.raises(ValueError, match="camera must be one of"):
        Scene3D(size=SIZE, camera="overhead")
    with pytest.raises(ValueError, match="background must be"):
        parse_background("purple")
    with Scene3D(size=SIZE) as empty:
        with pytest.raises(ValueError, match="empty"):
            empty.render()
        with pytest.raises(TypeError, match="puppet"):
            empty.add(object())
        handle = empty.add(np.zeros((3, 3)) + np.eye(3), np.array([[0, 1, 2]]))
        with pytest.raises(ValueError, match="expected 3 vertices"):
            empty.update(handle, np.zeros((4, 3)))


class _Stepping(_Blob):
    """A blob that grows by its 'grow' target each step."""

    target_names = ("grow",)

    def step(self, dt, targets):
        self.x = self.rest * (1.0 + targets.get("grow", 0.0))


def test_record_writes_one_png_per_frame(tmp_path):
    from PIL import Image
    from mop.render.scene3d import record
    blob = _Stepping()
    count = record(blob, [{"grow": g} for g in (0.0, 0.3, 0.6)], tmp_path / "frames",
                   size=SIZE, camera="front", background="transparent")
    files = sorted((tmp_path / "frames").glob("*.png"))
    assert count == 3 and len(files) == 3
    shares = [np.asarray(Image.open(f).convert("RGBA"))[..., 3].astype(bool).mean() for f in files]
    assert shares[0] < shares[1] < shares[2]


def test_closing_one_scene_leaves_the_others_working():
    first = Scene3D(size=SIZE, camera="front")
    second = Scene3D(size=SIZE, camera="front")
    try:
        first.add(_Blob())
        second.add(_Blob())
        before = second.render()
        first.close()
        after = second.render()
        np.testing.assert_array_equal(before, after)
        third = Scene3D(size=SIZE, camera="front")
        third.add(_Blob())
        np.testing.assert_array_equal(third.render(), before)
        third.close()
    finally:
        first.close()
        second.close()
