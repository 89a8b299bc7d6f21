"""Image puppets: background removal on real photographs, the grid mesh, springs and ARAP
simulation, baking, and the errors for bad input."""
import json

import numpy as np
import pytest

from characters import ImagePuppet, Motion
from characters.image.arap import R90, ArapDeformer
from characters.image.background import load_image, remove_background
from characters.image.bake import key_times
from characters.image.mesh import even_odd_inside, signed_areas
from characters.integrators import Verlet

cv2 = pytest.importorskip("cv2")


# --- real photographs composited over plain, noisy backgrounds ----------------------------

def _photo() -> np.ndarray:
    cbook = pytest.importorskip("matplotlib.cbook")
    return load_image(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))


def _blob_mask(rng, height, width, *, lobes=5) -> np.ndarray:
    """A random smooth star-like shape (concave, with lobes) filling much of the frame."""
    theta = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    radius = np.ones_like(theta)
    for k in range(2, lobes + 2):
        radius += rng.uniform(0.03, 0.12) * np.cos(k * theta + rng.uniform(0, 2 * np.pi))
    scale = 0.36 * min(height, width) / radius.max()
    centre = np.array([width / 2, height / 2]) + rng.uniform(-0.05, 0.05, 2) * [width, height]
    points = centre + scale * radius[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)
    mask = np.zeros((height, width), np.uint8)
    cv2.fillPoly(mask, [np.round(points).astype(np.int32)], 1)
    return mask.astype(bool)


def _composite(photo, mask, colour, rng, noise=8.0):
    background = np.asarray(colour, float) + rng.normal(0.0, noise, photo.shape)
    background = np.clip(np.round(background), 0, 255).astype(np.uint8)
    return np.where(mask[:, :, None], photo, background)


def _iou(a, b) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.mark.realdata
@pytest.mark.parametrize("colour", [(40, 200, 60), (230, 40, 200), (60, 90, 200)],
                         ids=["green", "magenta", "blue"])
def test_mask_iou_on_real_photo_composites(colour, rng):
    """Colour keying needs a background colour the character does not show at its edge (a
    white background eats this photo's white collar: see the README's limits)."""
    photo = _photo()
    for crop in (photo[:420, :], photo[150:, 40:]):
        crop = np.ascontiguousarray(crop)
        truth = _blob_mask(rng, *crop.shape[:2])
        picture = _composite(crop, truth, colour, rng)
        found = remove_background(picture).mask
        assert _iou(found, truth) >= 0.95, _iou(found, truth)


@pytest.mark.realdata
def test_grey_photo_composite_and_array_kinds(rng):
    photo = _photo()[:400, :400]
    grey = np.ascontiguousarray(photo.mean(axis=2).astype(np.uint8))
    truth = _blob_mask(rng, 400, 400)
    noise = rng.normal(0, 6, grey.shape)
    picture = np.where(truth, grey, np.clip(235 + noise, 0, 255)).astype(np.uint8)
    # grey photos are darker than the light background except a few highlights
    assert _iou(remove_background(load_image(picture)).mask, truth) >= 0.95
    # float in [0, 1] and (H, W, 1) give the same mask
    as_float = load_image(picture[:, :, None].astype(np.float64) / 255.0)
    assert np.array_equal(remove_background(as_float).mask,
                          remove_background(load_image(picture)).mask)


@pytest.mark.realdata
def test_real_alpha_channel_is_used():
    cbook = pytest.importorskip("matplotlib.cbook")
    from PIL import Image
    clipart = np.asarray(Image.open(cbook.get_sample_data("Minduka_Present_Blue_Pack.png"))
                         .convert("RGBA"))
    cut = remove_background(load_image(clipart))
    alpha = clipart[:, :, 3] >= 128
    count, labels, stats, _ = cv2.connectedComponentsWithStats(alpha.astype(np.uint8), 8)
    largest = labels == 1 + np.argmax(stats[1:, cv2.CC_STAT_AREA])
    assert cut.background_colour is None
    # the largest opaque part, its small enclosed holes filled
    assert np.all(cut.mask >= largest)
    assert _iou(cut.mask, largest) >= 0.99
    # the picture's own soft edge is kept where the character is
    assert np.array_equal(cut.rgba[:, :, 3][cut.mask], clipart[:, :, 3][cut.mask])


def test_holes_near_background_colour_are_filled_real_gaps_kept(rng):
    """White eyes on a cream background stay; the background seen through a ring goes."""
    cream = (246, 241, 228)
    picture = np.empty((200, 300, 3), np.uint8)
    picture[...] = cream
    cv2.circle(picture, (90, 100), 70, (200, 80, 40), -1)        # a face ...
    cv2.circle(picture, (70, 80), 14, (255, 255, 255), -1)       # ... with white eyes
    cv2.circle(picture, (110, 80), 14, (255, 255, 255), -1)
    cv2.circle(picture, (220, 100), 60, (40, 80, 200), -1)       # a ring joined to the face
    cv2.circle(picture, (220, 100), 30, cream, -1)
    cv2.rectangle(picture, (150, 95), (170, 105), (40, 80, 200), -1)
    mask = remove_background(picture).mask
    assert mask[80, 70] and mask[80, 110], "white eyes must stay part of the character"
    assert not mask[100, 220], "background seen through the ring must be a hole"


def test_feathered_alpha_edge():
    picture = np.full((120, 120, 3), 250, np.uint8)
    cv2.circle(picture, (60, 60), 40, (30, 60, 150), -1)
    cut = remove_background(picture, feather=3.0)
    alpha = cut.rgba[:, :, 3]
    assert alpha[60, 60] == 255 and alpha[5, 5] == 0
    edge = alpha[cut.mask & (alpha < 255)]
    assert edge.size > 0 and edge.min() > 0, "the edge ramps, it is not cut hard"
    assert np.all(alpha[~cut.mask] == 0), "no background colour halo outside the character"
    hard = remove_background(picture, feather=0.0).rgba[:, :, 3]
    assert set(np.unique(hard)) == {0, 255}


# --- the mesh -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def momo_path():
    from pathlib import Path

    import characters
    return Path(characters.__file__).parent / "assets" / "momo.png"


@pytest.fixture(scope="module")
def momo(momo_path):
    return ImagePuppet.from_image(momo_path)


@pytest.mark.slow
def test_even_odd_against_opencv(rng):
    mask = _blob_mask(rng, 160, 200)
    mask[60:80, 90:110] = False   # a hole
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    polygons = [c.reshape(-1, 2).astype(float) for c in contours]
    points = rng.uniform([0, 0], [200, 160], (3000, 2))
    inside = np.zeros(len(points), bool)
    even_odd_inside(points, np.concatenate(polygons),
                    np.cumsum([0] + [len(p) for p in polygons]), inside)
    # reference: OpenCV's signed distance to each polygon, parity of containment
    distances = np.array([[cv2.pointPolygonTest(p.astype(np.float32).reshape(-1, 1, 2),
                                                (float(x), float(y)), True)
                           for p in polygons] for x, y in points])
    clear = np.all(np.abs(distances) > 0.5, axis=1)   # not on an edge
    reference = (distances > 0).sum(1) % 2 == 1
    assert clear.sum() > 2500
    assert np.array_equal(inside[clear], reference[clear])


def _triangle_coverage(vertices, triangles, shape):
    """Slow reference: every pixel centre inside (or on) some triangle."""
    covered = np.zeros(shape, bool)
    for tri in vertices[triangles]:
        low = np.floor(tri.min(0)).astype(int)
        high = np.ceil(tri.max(0)).astype(int)
        xs, ys = np.meshgrid(np.arange(low[0], high[0] + 1), np.arange(low[1], high[1] + 1))
        p = np.stack([xs.ravel(), ys.ravel()], 1).astype(float)
        a, b, c = tri
        d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        w1 = ((p[:, 0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (p[:, 1] - a[1])) / d
        w2 = ((b[0] - a[0]) * (p[:, 1] - a[1]) - (p[:, 0] - a[0]) * (b[1] - a[1])) / d
        ok = (w1 >= -1e-9) & (w2 >= -1e-9) & (w1 + w2 <= 1 + 1e-9)
        ok &= (p[:, 0] >= 0) & (p[:, 1] >= 0) & (p[:, 0] < shape[1]) & (p[:, 1] < shape[0])
        covered[p[ok, 1].astype(int), p[ok, 0].astype(int)] = True
    return covered


def test_mesh_covers_character_and_little_background(momo):
    covered = _triangle_coverage(momo.vertices, momo.triangles, momo.mask.shape)
    assert np.all(covered[momo.mask]), "every character pixel lies in a kept triangle"
    assert np.all(covered[momo.image[:, :, 3] > 0]), "and every pixel with some alpha"
    meshed_background = (covered & ~momo.mask).sum() / covered.sum()
    assert meshed_background < 0.25, meshed_background


def test_mesh_structure(momo):
    areas = signed_areas(momo.vertices, momo.triangles)
    assert np.all(areas > 0)
    cell = momo.cell_size
    assert np.allclose(areas, cell * cell / 2)
    # springs: every triangle edge is a spring, plus the other diagonal of each cell
    springs = {tuple(s) for s in np.sort(momo.springs, axis=1)}
    assert len(springs) == len(momo.springs)
    edges = {tuple(sorted((t[i], t[(i + 1) % 3]))) for t in momo.triangles for i in range(3)}
    assert edges <= springs
    cells = len(momo.triangles) // 2
    assert len(springs) - len(edges) == cells
    lengths = np.linalg.norm(np.diff(momo.vertices[momo.springs], axis=1)[:, 0], axis=1)
    assert np.allclose(np.sort(np.unique(np.round(lengths / cell, 6))), [1, np.sqrt(2)])
    assert np.all(momo.model.mass == momo.model.mass[0])
    height, width = momo.mask.shape
    assert np.allclose(momo.uv * [width, height] - 0.5, momo.vertices)
    assert momo.uv.min() >= 0 and momo.uv.max() <= 1


def test_cell_size_sets_grid(momo_path):
    coarse = ImagePuppet.from_image(momo_path, cell_size=32)
    fine = ImagePuppet.from_image(momo_path, cell_size=12)
    assert coarse.cell_size == 32 and fine.cell_size == 12
    assert len(fine.vertices) > 5 * len(coarse.vertices)


@pytest.mark.slow
def test_large_picture_meshed_downscaled_rendered_full_size(momo_path):
    from PIL import Image
    big = np.asarray(Image.open(momo_path).resize((2048, 2048), Image.BICUBIC))
    puppet = ImagePuppet.from_image(big, max_mesh_size=512)
    small = ImagePuppet.from_image(cv2.resize(big, (512, 512), interpolation=cv2.INTER_AREA))
    assert puppet.mesh_scale == pytest.approx(0.25)
    assert puppet.mask.shape == (2048, 2048) and puppet.image.shape == (2048, 2048, 4)
    # the mesh is built on the mask downscaled to 512: the small picture's grid, scaled back
    assert puppet.cell_size == pytest.approx(4 * small.cell_size, rel=0.02)
    assert abs(len(puppet.triangles) - len(small.triangles)) <= 0.1 * len(small.triangles)
    upscaled = cv2.resize(small.mask.astype(np.uint8), (2048, 2048),
                          interpolation=cv2.INTER_NEAREST).astype(bool)
    assert _iou(puppet.mask, upscaled) > 0.97
    # every pixel with some alpha lies on the rest mesh (rendered at full size)
    covered = _triangle_coverage(puppet.vertices, puppet.triangles, puppet.mask.shape)
    assert np.all(covered[puppet.image[:, :, 3] > 0])
    # pins are given in full-size pixels
    index = puppet.add_pin((1024, 440))
    assert np.linalg.norm(puppet.vertices[index] - (1024, 440)) <= puppet.cell_size


# --- simulation -----------------------------------------------------------------------------

def _pinned(path, **kwargs):
    puppet = ImagePuppet.from_image(path, **kwargs)
    puppet.add_pin((196, 470), name="left_foot", fixed=True)
    puppet.add_pin((316, 470), name="right_foot", fixed=True)
    puppet.add_pin((256, 110), name="head")
    return puppet


@pytest.mark.slow
def test_rest_stays_at_rest(momo_path):
    for mode in ("springs", "arap"):
        puppet = _pinned(momo_path, mode=mode)
        for _ in range(50):
            puppet.step(1 / 25, {})
        assert np.abs(puppet.surface() - puppet.vertices).max() < 1e-6
        for _ in range(10):   # a driven pin held exactly at its rest position changes nothing
            puppet.step(1 / 25, {"head": puppet.vertices[puppet.pins["head"].index]})
        assert np.abs(puppet.surface() - puppet.vertices).max() < 1e-6
        assert np.abs(puppet.state.v).max() < 1e-4


@pytest.mark.parametrize("direction", [(1, 0), (0, -1), (-0.7, 0.7), (0, 1)],
                         ids=["sideways", "up", "down-left", "down-into-the-anchors"])
def test_rubber_pull_by_30_percent_inverts_nothing(momo_path, direction):
    puppet = _pinned(momo_path, material="rubber")
    size = (puppet.vertices.max(0) - puppet.vertices.min(0)).max()
    head = puppet.vertices[puppet.pins["head"].index]
    goal = head + 0.3 * size * np.asarray(direction) / np.linalg.norm(direction)
    motion = Motion({"head": ([0.0, 0.5, 2.0], [head, goal, goal])})
    shapes = puppet.simulate(motion, fps=25)
    areas = np.array([signed_areas(s, puppet.triangles).min() for s in shapes])
    assert np.all(areas > 0), f"inverted at frames {np.flatnonzero(areas <= 0)}"
    assert np.allclose(shapes[-1][puppet.pins["head"].index], goal)
    assert puppet.inverted_triangles().size == 0



def test_the_compiled_frame_steps_as_the_substep_loop(momo_path):
    """One compiled call per frame against the integrator's Python substep loop, on the same
    pins: a head pushed down into the anchored feet (the no-fold guard at work), held, then
    let go: the same states, bit for bit, and the same guard count."""
    compiled, looped = (_pinned(momo_path, material="rubber") for _ in range(2))
    assert compiled._integrator._frame is not None
    looped._integrator = Verlet(substeps=1)      # the base class's loop
    head = compiled.vertices[compiled.pins["head"].index]
    folded = 0
    for k in range(40):
        targets = ({"head": head + (25.0 * np.sin(0.5 * k), 9.0 * min(k, 20))} if k < 30
                   else {})
        compiled.step(1 / 25, targets)
        looped.step(1 / 25, targets)
        np.testing.assert_array_equal(compiled.state.x, looped.state.x)
        np.testing.assert_array_equal(compiled.state.v, looped.state.v)
        assert compiled._no_fold.last_below == looped._no_fold.last_below
        folded = max(folded, compiled._no_fold.last_below)
    assert folded > 10                              # the guard had triangles to push apart
    assert np.abs(compiled.surface() - compiled.vertices).max() > 10.0

def test_pulled_pin_drags_neighbours_more_than_far_side(momo_path):
    puppet = ImagePuppet.from_image(momo_path)       # no anchors: only inertia holds it back
    index = puppet.add_pin((66, 172), name="hand")
    hand = puppet.vertices[index]
    motion = Motion({"hand": ([0.0, 0.2], [hand, hand + (-60.0, -40.0)])})
    shape = puppet.simulate(motion, fps=50)[-1]
    moved = np.linalg.norm(shape - puppet.vertices, axis=1)
    distance = np.linalg.norm(puppet.vertices - hand, axis=1)
    near = (distance > 0) & (distance <= 2.5 * puppet.cell_size)
    far = distance >= np.percentile(distance, 75)
    assert moved[near].mean() > 3 * moved[far].mean()
    assert moved[near].mean() > 20.0


@pytest.mark.slow
def test_stiffer_materials_carry_a_pull_further(momo_path):
    """With no anchors, a pull on the head reaches the feet sooner the stiffer the material
    (the presets of characters/materials.toml); unknown names are rejected."""
    arrival = {}
    for name in ("liquid", "fabric", "rubber", "rigid"):
        puppet = ImagePuppet.from_image(momo_path, material=name)
        puppet.add_pin((256, 110), name="head")
        head = puppet.vertices[puppet.pins["head"].index]
        goal = head + (0, -60.0)
        motion = Motion({"head": ([0.0, 0.2, 2.0], [head, goal, goal])})
        shapes = puppet.simulate(motion, fps=25)
        feet = puppet.vertices[:, 1] > 440
        moved = np.abs(shapes[:, feet, 1] - puppet.vertices[feet, 1]).mean(1)
        arrived = np.flatnonzero(moved > 10.0)
        arrival[name] = arrived[0] / 25 if arrived.size else np.inf
    assert arrival["rigid"] < arrival["rubber"] < arrival["fabric"] < arrival["liquid"], arrival
    assert arrival["rubber"] < 1.0
    with pytest.raises(ValueError, match=r"unknown material 'jelly' for an image puppet; "
                                         r"choose one of \['liquid', 'fabric', 'rubber', "
                                         r"'rigid'\]"):
        ImagePuppet.from_image(momo_path, material="jelly")
    with pytest.raises(ValueError, match="'latex_foam' \\(latex\\) has no per-mass spring"):
        ImagePuppet.from_image(momo_path, material="latex_foam")


def test_no_fold_constraint_unfolds_and_respects_immovable_vertices(rng):
    from characters.image.guard import NoFoldConstraint
    rest, triangles = _small_grid(4)
    guard = NoFoldConstraint(triangles, rest, min_area_fraction=0.2, iterations=50)
    x = rest + rng.normal(0, 6.0, rest.shape)          # crumpled: many triangles flipped
    assert np.any(signed_areas(x, triangles) <= 0)
    v = np.zeros_like(x)
    weights = np.ones(len(x))
    weights[[0, 5]] = 0.0                               # as if pinned
    before = x.copy()
    guard.apply(x, v, 0.01, weights)
    assert np.all(signed_areas(x, triangles) >= 0.2 * signed_areas(rest, triangles) - 1e-6)
    assert np.array_equal(x[[0, 5]], before[[0, 5]])
    assert np.allclose(v, (x - before) / 0.01), "corrections change velocities by dx / h"
    untouched = rest.copy()
    guard.apply(untouched, np.zeros_like(rest), 0.01, weights)
    assert np.array_equal(untouched, rest), "a mesh at rest is left alone"


# --- ARAP -----------------------------------------------------------------------------------

def _small_grid(n=5, cell=10.0):
    xs, ys = np.meshgrid(np.arange(n) * cell, np.arange(n) * cell)
    rest = np.stack([xs.ravel(), ys.ravel()], 1)
    triangles = []
    for r in range(n - 1):
        for c in range(n - 1):
            a, b, d = r * n + c, r * n + c + 1, (r + 1) * n + c
            triangles += [[a, b, d + 1], [a, d + 1, d]] if (r + c) % 2 == 0 else [[a, b, d],
                                                                                   [b, d + 1, d]]
    return rest, np.array(triangles)


def _arap_dense_reference(rest, triangles, handles, positions):
    """Igarashi et al. 2005 written out with dense matrices and least squares."""
    n = len(rest)
    free = [i for i in range(n) if i not in set(handles.tolist())]

    def solve_constrained(rows):
        """min |A v|^2 over interleaved v (2N,) with the handles' coordinates fixed."""
        a = np.array(rows)
        fixed = np.zeros(a.shape[1])
        for h, p in zip(handles, positions):
            fixed[2 * h:2 * h + 2] = p
        columns = [2 * i + d for i in free for d in range(2)]
        solution, *_ = np.linalg.lstsq(a[:, columns], -a @ fixed, rcond=None)
        fixed[columns] = solution
        return fixed

    # step 1: each vertex relative to its opposite edge, rotation + scale allowed
    rows = []
    for tri in triangles:
        for k in range(3):
            i, j, o = tri[(k + 1) % 3], tri[(k + 2) % 3], tri[k]
            e = rest[j] - rest[i]
            x = np.dot(rest[o] - rest[i], e) / np.dot(e, e)
            y = np.dot(rest[o] - rest[i], R90 @ e) / np.dot(e, e)
            block = np.zeros((2, 2 * n))
            block[:, 2 * o:2 * o + 2] += np.eye(2)
            block[:, 2 * i:2 * i + 2] -= (1 - x) * np.eye(2) - y * R90
            block[:, 2 * j:2 * j + 2] -= x * np.eye(2) + y * R90
            rows.extend(block)
    step1 = solve_constrained(rows).reshape(n, 2)

    # step 2a: fit each rest triangle (similarity) to step 1 by least squares, rescale
    edges, vectors = [], []
    for tri in triangles:
        p = rest[tri]
        e = p[1] - p[0]
        x = np.dot(p[2] - p[0], e) / np.dot(e, e)
        y = np.dot(p[2] - p[0], R90 @ e) / np.dot(e, e)
        m0, m1 = (1 - x) * np.eye(2) - y * R90, x * np.eye(2) + y * R90
        a = np.zeros((6, 4))
        a[0:2, 0:2] = np.eye(2)
        a[2:4, 2:4] = np.eye(2)
        a[4:6, 0:2] = m0
        a[4:6, 2:4] = m1
        w, *_ = np.linalg.lstsq(a, step1[tri].ravel(), rcond=None)
        fit = a @ w
        fit = fit.reshape(3, 2)
        scale = np.linalg.norm(e) / np.linalg.norm(fit[1] - fit[0])
        fit = fit.mean(0) + (fit - fit.mean(0)) * scale
        for u, v in ((0, 1), (1, 2), (2, 0)):
            edges.append((tri[u], tri[v]))
            vectors.append(fit[v] - fit[u])
    # step 2b: match the fitted edge vectors, x and y separately
    incidence = np.zeros((len(edges), n))
    for row, (i, j) in enumerate(edges):
        incidence[row, j], incidence[row, i] = 1.0, -1.0
    vectors = np.array(vectors)
    out = np.zeros((n, 2))
    free = np.setdiff1d(np.arange(n), handles)
    for d in range(2):
        out[handles, d] = positions[:, d]
        rhs = vectors[:, d] - incidence[:, handles] @ positions[:, d]
        out[free, d] = np.linalg.lstsq(incidence[:, free], rhs, rcond=None)[0]
    return out


def test_arap_matches_dense_reference(rng):
    rest, triangles = _small_grid()
    deformer = ArapDeformer(rest, triangles)
    handles = np.array([0, 4, 22])
    positions = rest[handles] + rng.normal(0, 8, (3, 2))
    fast = deformer.deform(handles, positions)
    slow = _arap_dense_reference(rest, triangles, handles, positions)
    assert np.abs(fast - slow).max() < 1e-8
    # and it is a real deformation, not the rest shape
    assert np.abs(fast - rest).max() > 5


def test_arap_reproduces_rigid_motions_and_factorises_once(rng):
    rest, triangles = _small_grid(6)
    deformer = ArapDeformer(rest, triangles)
    handles = np.array([0, 17, 35])
    for angle in (0.3, 1.2, -2.0):
        rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        moved = rest @ rotation.T + rng.normal(0, 20, 2)
        assert np.abs(deformer.deform(handles, moved[handles]) - moved).max() < 1e-9
    assert deformer.factorisations == 1, "the same handle set reuses its factorisation"
    deformer.deform(handles[:2], rest[handles[:2]] + 1)
    assert deformer.factorisations == 2
    # one handle only: the rest shape translated
    assert np.allclose(deformer.deform([7], [rest[7] + (3, 4)]), rest + (3, 4))


def test_arap_puppet_keeps_shape_better_than_its_pull_and_no_inversion(momo_path):
    puppet = _pinned(momo_path, mode="arap")
    size = (puppet.vertices.max(0) - puppet.vertices.min(0)).max()
    head = puppet.vertices[puppet.pins["head"].index]
    goal = head + (0.3 * size, 0.0)
    puppet.step(1 / 25, {"head": goal})
    shape = puppet.surface()
    assert np.allclose(shape[puppet.pins["head"].index], goal)
    assert np.all(signed_areas(shape, puppet.triangles) > 0)
    # an ARAP frame depends on the pins only: the same targets give the same shape
    puppet.step(1 / 25, {"head": head})
    puppet.step(1 / 25, {"head": goal})
    assert np.allclose(puppet.surface(), shape)
    assert puppet._arap.factorisations == 1


# --- baking ---------------------------------------------------------------------------------

def _momo_with_motion(momo_path, mode="springs"):
    import characters
    from pathlib import Path
    data = json.loads((Path(characters.__file__).parent / "assets" / "momo_wave.json").read_text())
    puppet = ImagePuppet.from_image(momo_path, mode=mode)
    for name, pin in data["pins"].items():
        puppet.add_pin(pin["xy"], name=name, fixed=pin.get("fixed", False))
    return puppet, Motion.from_dict(data)


def test_key_times_include_motion_keys_and_bound_gaps():
    motion = Motion({"a": ([0.0, 0.25, 1.0], [[0, 0], [1, 1], [1, 1]]),
                     "b": ([0.6], [[0, 0]])})
    keys = key_times(motion, duration=1.0, max_interval=0.2)
    for t in (0.0, 0.25, 0.6, 1.0):
        assert np.any(np.isclose(keys, t))
    assert np.all(np.diff(keys) <= 0.2 + 1e-12) and np.all(np.diff(keys) > 0)


@pytest.mark.parametrize("mode", ["springs", "arap"])
@pytest.mark.slow
def test_baked_playback_deviation_is_bounded(momo_path, mode):
    puppet, motion = _momo_with_motion(momo_path, mode)
    fps = 25.0
    simulated = puppet.simulate(motion, fps=fps)
    baked = puppet.bake(motion, fps=fps, max_interval=0.1)
    times = np.arange(len(simulated)) / fps
    errors = baked.deviation(times, simulated)
    assert baked.deviation_max == pytest.approx(errors.max())
    # keys are exact, and the article's keys-only playback stays close
    for t, _shape in zip(baked.times, baked.shapes):
        assert np.array_equal(baked.shape_at(t), simulated[int(round(t * fps))])
    assert baked.key_count < 0.6 * len(simulated)   # 49 keys for 101 frames here
    assert errors.max() < 12.0, errors.max()
    assert errors.mean() < 3.0, errors.mean()
    # denser keys never do worse; a key every frame is exact
    dense = puppet.bake(motion, fps=fps, max_interval=0.04)
    assert dense.deviation_max <= baked.deviation_max + 1e-9
    assert dense.deviation_max == pytest.approx(0.0, abs=1e-9)
    # linear blending, as the article's shader: 3/4 of the way between two keys
    t0, t1 = baked.times[3], baked.times[4]
    blended = baked.shape_at(t0 + 0.75 * (t1 - t0))
    assert np.allclose(blended, 0.25 * baked.shapes[3] + 0.75 * baked.shapes[4])


def test_baked_motion_save_load(tmp_path, momo_path):
    puppet, motion = _momo_with_motion(momo_path, "arap")
    baked = puppet.bake(motion, fps=10.0, max_interval=0.5)
    baked.save(tmp_path / "bake.npz")
    loaded = type(baked).load(tmp_path / "bake.npz")
    assert np.array_equal(loaded.times, baked.times)
    assert np.array_equal(loaded.shapes, baked.shapes)
    assert loaded.deviation_max == baked.deviation_max


# --- bad input ------------------------------------------------------------------------------

def test_uniform_image_is_rejected():
    with pytest.raises(ValueError, match="image is uniform"):
        ImagePuppet.from_image(np.full((64, 64, 3), 128, np.uint8))
    with pytest.raises(ValueError, match="fully transparent"):
        ImagePuppet.from_image(np.zeros((64, 64, 4), np.uint8))


def test_no_separable_foreground_is_rejected(rng):
    noise = rng.integers(0, 256, (128, 128, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match="the background is not plain"):
        ImagePuppet.from_image(noise)
    photo = _photo()
    with pytest.raises(ValueError, match="the background is not plain: .* varies by"):
        ImagePuppet.from_image(photo)
    speck = np.full((200, 200, 3), 240, np.uint8)
    speck[100:103, 100:103] = 0
    with pytest.raises(ValueError, match="no separable foreground: the largest part .* 9 pixels"):
        ImagePuppet.from_image(speck)


def test_tiny_and_enormous_images_are_rejected(tmp_path):
    with pytest.raises(ValueError, match=r"image is 8x10 pixels: too small.*16x16"):
        ImagePuppet.from_image(np.zeros((10, 8, 3), np.uint8))
    with pytest.raises(ValueError, match=r"image is 9000x16 pixels: larger than the supported "
                                         r"8192 per side"):
        load_image(np.zeros((16, 9000, 3), np.uint8))
    with pytest.raises(FileNotFoundError, match="image file not found"):
        ImagePuppet.from_image(tmp_path / "missing.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ValueError, match="not an image Pillow can read"):
        ImagePuppet.from_image(tmp_path / "text.png")
    with pytest.raises(ValueError, match=r"float image must hold values in \[0, 1\]"):
        load_image(np.full((20, 20), 3.0))
    with pytest.raises(TypeError, match="path or a numpy array"):
        ImagePuppet.from_image([[1, 2], [3, 4]])


def test_bad_pins_and_targets(momo_path):
    puppet = ImagePuppet.from_image(momo_path)
    with pytest.raises(ValueError, match=r"pin 'tail' at \(20, 20\) is outside the character "
                                         r"\(512x512 px\); the nearest mesh vertex is \d+ px away"):
        puppet.add_pin((20, 20), name="tail")
    with pytest.raises(ValueError, match="outside the picture"):
        puppet.add_pin((900, 100), name="far")
    puppet.add_pin((256, 110), name="head")
    with pytest.raises(ValueError, match="a pin named 'head' exists already"):
        puppet.add_pin((66, 172), name="head")
    with pytest.raises(ValueError, match="already used by pin 'head'"):
        puppet.add_pin((257, 111), name="head2")
    puppet.add_pin((196, 470), name="foot", fixed=True)
    assert puppet.target_names == ("head",)
    with pytest.raises(ValueError, match=r"target 'hand' is not a pin; this puppet's targets "
                                         r"are \['head'\]"):
        puppet.step(0.04, {"hand": (1, 2)})
    with pytest.raises(ValueError, match="'foot' is a fixed pin"):
        puppet.step(0.04, {"foot": (1, 2)})
    with pytest.raises(ValueError, match=r"target 'head' must be a finite \(x, y\)"):
        puppet.step(0.04, {"head": (1, 2, 3)})
    motion = Motion({"head": ([0, 1], [[256, 110], [256, 90]]),
                     "tail": ([0, 1], [[1, 1], [2, 2]])})
    with pytest.raises(ValueError, match=r"the motion drives \['tail'\] but this puppet has no "
                                         r"driven pin of that name; its driven pins are "
                                         r"\['head'\]"):
        puppet.simulate(motion, fps=25)
    with pytest.raises(ValueError, match="mode must be one of"):
        ImagePuppet.from_image(momo_path, mode="magic")
    with pytest.raises(ValueError, match="cell_size 0.5 px is too small"):
        ImagePuppet.from_image(momo_path, cell_size=0.5)
