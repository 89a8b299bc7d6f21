"""The latex puppet's geometry kernels against slow, obvious references: inside tests and
distances (trimesh), decimation priorities (a Python re-derivation of section 4.1), the
decimated surface's properties against plain quadric decimation (fast-simplification), the
internal layers (4.2) and the connection map's nearest-vertex search (scipy's Dijkstra)."""
import math
import os

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from characters.latex import decimate as dec  # noqa: E402
from characters.latex.connection import (build_connection, edge_graph,  # noqa: E402
                                               nearest_sources)
from characters.latex.layers import build_layers, tetrahedron_volumes  # noqa: E402
from characters.latex.regions import Opening, parse_regions  # noqa: E402
from characters.latex.surface import (InsideTest, SurfaceDistance,  # noqa: E402
                                            clean_surface, edge_use_counts, load_mesh)


def _pybullet_mesh(name):
    pybullet_data = pytest.importorskip("pybullet_data")
    loaded = load_mesh(os.path.join(pybullet_data.getDataPath(), name))
    return clean_surface(loaded.vertices, loaded.faces, source=name)


@pytest.fixture(scope="module")
def bunny():
    return _pybullet_mesh("bunny.obj")


@pytest.fixture(scope="module")
def duck():
    return _pybullet_mesh("duck.obj")


# --- surfaces -----------------------------------------------------------------------------------

@pytest.mark.realdata
@pytest.mark.slow
def test_inside_test_matches_trimesh_contains(bunny, rng):
    lo, hi = bunny.vertices.min(0), bunny.vertices.max(0)
    points = rng.uniform(lo, hi, (1500, 3))
    ours = InsideTest(bunny.vertices, bunny.faces)(points)
    reference = trimesh.Trimesh(bunny.vertices, bunny.faces, process=False).contains(points)
    assert 0.1 < ours.mean() < 0.9  # both answers occur
    np.testing.assert_array_equal(ours, reference)


@pytest.mark.realdata
def test_surface_distance_matches_trimesh_closest_point(bunny, rng):
    lo, hi = bunny.vertices.min(0), bunny.vertices.max(0)
    points = rng.uniform(lo - 0.2, hi + 0.2, (300, 3))
    ours = SurfaceDistance(bunny.vertices, bunny.faces)(points)
    mesh = trimesh.Trimesh(bunny.vertices, bunny.faces, process=False)
    _, reference, _ = trimesh.proximity.closest_point(mesh, points)
    np.testing.assert_allclose(ours, reference, atol=1e-12)


@pytest.mark.realdata
def test_duck_obj_seams_are_merged_into_a_closed_surface(duck):
    # duck.obj splits vertices along its texture seams: 2277 as stored, 2108 positions
    assert len(duck.vertices) == 2108
    assert any("merged 169 duplicate vertices" in r for r in duck.repairs)
    _, counts = edge_use_counts(duck.faces)
    assert np.all(counts == 2)


def test_clean_removes_degenerate_faces_and_maps_indices():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    v = np.concatenate([sphere.vertices, sphere.vertices[:1], [[5.0, 5.0, 5.0]]])
    extra = len(sphere.vertices)  # a duplicate of vertex 0, and an unused vertex after it
    f = np.concatenate([sphere.faces, [[0, 1, 1], [2, 3, 2]]])  # two degenerate faces
    f[f == 0] = np.where(np.arange(f.size).reshape(f.shape)[f == 0] % 2 == 0, 0, extra)
    clean = clean_surface(v, f)
    assert any("degenerate" in r for r in clean.repairs)
    assert len(clean.vertices) == len(sphere.vertices)
    assert clean.index_map[extra] == clean.index_map[0]
    assert clean.index_map[extra + 1] == -1
    np.testing.assert_allclose(clean.vertices[clean.index_map[:extra]], sphere.vertices)


def test_open_surface_is_repaired_or_rejected_naming_the_holes():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    one_face_missing = clean_surface(sphere.vertices, sphere.faces[1:])
    assert any("filled holes" in r for r in one_face_missing.repairs)
    centroids = sphere.vertices[sphere.faces].mean(1)
    cap_missing = sphere.faces[centroids[:, 2] < 0.7]
    with pytest.raises(ValueError, match=r"open.*16 boundary edges in 1 loop.*hole 1: 16 edges"):
        clean_surface(sphere.vertices, cap_missing)


def test_inward_wound_surface_is_turned_outward():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    clean = clean_surface(sphere.vertices, sphere.faces[:, ::-1])
    assert trimesh.Trimesh(clean.vertices, clean.faces, process=False).volume > 0


# --- decimation (4.1) -------------------------------------------------------------------------

def _reference_cost(vertices, faces, v, *, lam, cos_tau, h):
    """Section 4.1 re-derived in plain Python for one vertex: {neighbour: cost} of every valid
    half-edge collapse."""
    ring = faces[(faces == v).any(1)]
    normal = sum(np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a]) for a, b, c in ring)
    normal = normal / np.linalg.norm(normal)
    neighbours = sorted(set(ring.ravel()) - {v})
    quadrics = dec.plane_quadrics(vertices, faces)
    rows, cols = np.triu_indices(4)
    costs = {}
    for u in neighbours:
        ring_u = faces[(faces == u).any(1)]
        if len(set(neighbours) & (set(ring_u.ravel()) - {u})) != 2:
            continue
        new = []
        for face in ring:
            if u in face:
                continue
            new.append(np.where(face == v, u, face))
        normals_ok = True
        for old, face in zip([f for f in ring if u not in f], new):
            a, b, c = vertices[face]
            n = np.cross(b - a, c - a)
            a, b, c = vertices[old]
            n_old = np.cross(b - a, c - a)
            n = n / np.linalg.norm(n)
            if n @ normal < cos_tau or n @ n_old / np.linalg.norm(n_old) < cos_tau:
                normals_ok = False
        if not normals_ok:
            continue
        worst = max(1 - dec.roundness(vertices, np.array(new)))
        q = np.zeros((4, 4))
        q[rows, cols] = quadrics[u] + quadrics[v]
        q = q + np.triu(q, 1).T
        p = np.append(vertices[u], 1.0)
        costs[u] = lam * worst + (1 - lam) * math.sqrt(max(p @ q @ p, 0.0)) / h
    return costs


@pytest.mark.realdata
@pytest.mark.parametrize("lam", [0.0, 0.5, 1.0])
@pytest.mark.slow
def test_removal_priorities_match_a_python_rederivation(bunny, rng, lam):
    cost, target = dec.removal_costs(bunny.vertices, bunny.faces, target_vertices=150,
                                     roundness_weight=lam, normal_threshold=50.0)
    h = dec.target_edge_length(bunny.vertices, bunny.faces, 150)
    for v in rng.choice(len(bunny.vertices), 40, replace=False):
        costs = _reference_cost(bunny.vertices, bunny.faces, v, lam=lam,
                                cos_tau=math.cos(math.radians(50.0)), h=h)
        if not costs:
            assert math.isinf(cost[v]) and target[v] == -1
        else:
            assert cost[v] == pytest.approx(min(costs.values()), rel=1e-9, abs=1e-12)
            assert costs[int(target[v])] == pytest.approx(cost[v], rel=1e-9, abs=1e-12)


def test_roundness_of_known_triangles():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0.5, math.sqrt(3) / 2, 0],   # equilateral
                         [0, 0, 1], [1, 0, 1], [0, 1, 1],                    # right isosceles
                         [0, 0, 2], [1, 0, 2], [2, 0, 2]], dtype=float)      # degenerate
    r = dec.roundness(vertices, np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]]))
    # right isosceles: circumradius = hypotenuse / 2 = sqrt(2) / 2, shortest edge 1
    np.testing.assert_allclose(r, [1.0, (1 / math.sqrt(3)) / (math.sqrt(2) / 2), 0.0])


@pytest.mark.realdata
def test_decimated_surface_is_closed_keeps_locked_vertices_and_topology(duck, rng):
    locked = rng.choice(len(duck.vertices), 25, replace=False)
    result = dec.decimate(duck.vertices, duck.faces, target_vertices=300, locked=locked)
    assert len(result.kept) == 300 and not result.stopped_early
    assert set(locked) <= set(result.kept)
    _, counts = edge_use_counts(result.faces)
    assert np.all(counts == 2)
    euler = 300 - len(counts) + len(result.faces)
    assert euler == 2  # still a sphere
    v = duck.vertices[result.kept]
    assert trimesh.Trimesh(v, result.faces, process=False).volume > 0  # outward, not flipped


@pytest.mark.realdata
@pytest.mark.slow
def test_decimator_beats_plain_quadric_on_roundness_at_a_bounded_shape_cost(duck):
    ours = dec.decimate(duck.vertices, duck.faces, target_vertices=400, roundness_weight=0.5)
    ours_q = dec.quality(duck.vertices, duck.faces, duck.vertices[ours.kept], ours.faces,
                         samples=4000)
    ref_v, ref_f = dec.quadric_reference(duck.vertices, duck.faces, target_faces=len(ours.faces))
    ref_q = dec.quality(duck.vertices, duck.faces, ref_v, ref_f, samples=4000)
    assert ours_q.roundness_mean > ref_q.roundness_mean + 0.05
    assert ours_q.roundness_min > 3 * ref_q.roundness_min
    assert ours_q.sliver_share < 0.6 * ref_q.sliver_share
    # the price of round triangles: a larger, still small, shape error
    assert ours_q.hausdorff < 2.5 * ref_q.hausdorff
    assert ours_q.hausdorff_relative < 0.02


def test_normal_threshold_keeps_box_corners_and_blocks_flattening():
    box = trimesh.creation.box(extents=(1.0, 0.8, 0.6))
    box = box.subdivide().subdivide().subdivide()
    clean = clean_surface(box.vertices, box.faces)
    result = dec.decimate(clean.vertices, clean.faces, target_vertices=40, normal_threshold=30)
    corners = np.abs(np.abs(clean.vertices) - [0.5, 0.4, 0.3]).max(1) < 1e-9
    assert set(np.flatnonzero(corners)) <= set(result.kept)
    # the decimated box is still the box
    assert trimesh.Trimesh(clean.vertices[result.kept], result.faces).volume == pytest.approx(
        0.48, rel=1e-9)
    tight = dec.decimate(clean.vertices, clean.faces, target_vertices=8, normal_threshold=1.0)
    assert tight.stopped_early and len(tight.kept) > 8


def test_decimate_rejects_bad_parameters():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(ValueError, match="lambda"):
        dec.decimate(sphere.vertices, sphere.faces, target_vertices=20, roundness_weight=1.5)
    with pytest.raises(ValueError, match="normal_threshold"):
        dec.decimate(sphere.vertices, sphere.faces, target_vertices=20, normal_threshold=0)
    with pytest.raises(ValueError, match="target_vertices"):
        dec.decimate(sphere.vertices, sphere.faces, target_vertices=3)


# --- layers (4.2) ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sphere_layers():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    result = dec.decimate(sphere.vertices, sphere.faces, target_vertices=400)
    return sphere, result, build_layers(sphere.vertices[result.kept], result.faces,
                                        sphere.vertices, sphere.faces)


@pytest.mark.slow
def test_layers_are_three_nested_closed_shells(sphere_layers):
    sphere, result, layers = sphere_layers
    counts = np.bincount(layers.layer, minlength=3)
    assert counts[0] == 400 and counts[1] >= 50 and counts[2] >= 10
    np.testing.assert_array_equal(layers.points[:400], sphere.vertices[result.kept])
    depth = 1.0 - np.linalg.norm(layers.points, axis=1)  # distance below the unit sphere
    assert depth[layers.layer == 0].max() < 1e-9
    assert depth[layers.layer == 1].min() > 0.05
    assert np.median(depth[layers.layer == 2]) > np.median(depth[layers.layer == 1]) + 0.05
    # closed: (nearly) every node of a shell is tied by a spring to the shell below it
    low = np.minimum(layers.layer[layers.springs[:, 0]], layers.layer[layers.springs[:, 1]])
    high = np.maximum(layers.layer[layers.springs[:, 0]], layers.layer[layers.springs[:, 1]])
    for outer in (0, 1):
        ties = layers.springs[(low == outer) & (high == outer + 1)].ravel()
        assert np.isin(np.flatnonzero(layers.layer == outer), ties).mean() > 0.9


@pytest.mark.slow
def test_layer_tetrahedra_are_positive_inside_and_fill_the_solid(sphere_layers):
    sphere, _, layers = sphere_layers
    volume = tetrahedron_volumes(layers.points, layers.tetrahedra)
    assert volume.min() > 0
    assert volume.sum() == pytest.approx(sphere.volume, rel=0.1)
    centroids = layers.points[layers.tetrahedra].mean(1)
    assert np.all(np.linalg.norm(centroids, axis=1) < 1.0)
    # every tetrahedron edge and surface edge is a spring, once
    pairs = {tuple(p) for p in layers.springs}
    assert len(pairs) == len(layers.springs)
    for a, b in ((0, 1), (2, 3)):
        edge = np.sort(layers.tetrahedra[:, [a, b]], axis=1)
        assert all(tuple(e) in pairs for e in edge[:200])


def test_layers_explain_a_solid_too_thin_for_three_layers():
    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.02)).subdivide().subdivide().subdivide()
    clean = clean_surface(plate.vertices, plate.faces)
    result = dec.decimate(clean.vertices, clean.faces, target_vertices=60)
    with pytest.raises(ValueError, match="too few nodes for three layers.*ask for more masses"):
        build_layers(clean.vertices[result.kept], result.faces, clean.vertices, clean.faces)


# --- connection map (eq. 3-4) --------------------------------------------------------------------

@pytest.mark.realdata
def test_nearest_sources_match_scipy_dijkstra(bunny, rng):
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra
    starts, neighbours, lengths = edge_graph(bunny.vertices, bunny.faces)
    sources = np.sort(rng.choice(len(bunny.vertices), 60, replace=False))
    found, distance = nearest_sources(starts, neighbours, lengths, sources, 3)
    rows = np.repeat(np.arange(len(bunny.vertices)), np.diff(starts))
    graph = csr_matrix((lengths, (rows, neighbours)), shape=(len(bunny.vertices),) * 2)
    full = dijkstra(graph, indices=sources)  # (sources, V)
    expected = np.sort(full, axis=0)[:3].T
    np.testing.assert_allclose(distance, expected, rtol=1e-12)
    np.testing.assert_allclose(full[found, np.arange(len(bunny.vertices))[:, None]], distance,
                               rtol=1e-12)


@pytest.mark.realdata
def test_connection_weights_sum_to_one_and_fall_with_edge_distance(bunny, rng):
    kept = np.sort(rng.choice(len(bunny.vertices), 80, replace=False))
    conn = build_connection(bunny.vertices, bunny.faces, kept, connectors=3)
    w = conn.matrix()
    np.testing.assert_allclose(np.asarray(w.sum(1)).ravel(), 1.0, rtol=1e-12)
    assert conn.weights.min() > 0
    # a decimated vertex follows itself alone
    rows = w[kept].toarray()
    np.testing.assert_allclose(rows, np.eye(len(kept)))
    # moving every node by the same translation moves the visual mesh rigidly
    shift = np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(w @ np.tile(shift, (len(kept), 1)),
                               np.tile(shift, (len(bunny.vertices), 1)))


# --- regions --------------------------------------------------------------------------------------

def test_rotation_opening_turns_points_about_the_axis():
    opening = Opening("rotate", origin=(0.0, 1.0, 0.0), axis=(1.0, 0.0, 0.0), degrees=90.0)
    moved = opening.apply(np.array([[0.0, 1.0, 1.0], [2.0, 1.0, 0.0]]), 0.5)
    angle = math.radians(45.0)
    np.testing.assert_allclose(moved, [[0.0, 1.0 - math.sin(angle), math.cos(angle)],
                                       [2.0, 1.0, 0.0]], atol=1e-12)


def test_region_specs_reject_unknown_fingers_and_bad_openings(tmp_path):
    with pytest.raises(ValueError, match="unknown finger region 'toe'"):
        parse_regions({"toe": [1, 2]})
    with pytest.raises(ValueError, match="'open' must be 'rotate' or 'translate'"):
        parse_regions({"thumb": {"vertices": [1], "open": {"spin": 3}}})
    bad = tmp_path / "regions.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        parse_regions(bad)


@pytest.mark.realdata
@pytest.mark.slow
def test_barycentric_connection_lands_on_the_nearest_decimated_triangle(duck):
    result = dec.decimate(duck.vertices, duck.faces, target_vertices=300)
    conn = build_connection(duck.vertices, duck.faces, result.kept, weighting="barycentric",
                            surface_faces=result.faces)
    w = conn.matrix()
    np.testing.assert_allclose(np.asarray(w.sum(1)).ravel(), 1.0, rtol=1e-12)
    assert conn.weights.min() > 0 and np.diff(conn.indptr).max() <= 3
    nodes = duck.vertices[result.kept]
    landing = w @ nodes  # each vertex's point on the decimated surface
    gap = np.linalg.norm(landing - duck.vertices, axis=1)
    nearest = SurfaceDistance(nodes, result.faces)(duck.vertices)
    assert np.all(gap >= nearest - 1e-12)
    assert np.mean(np.isclose(gap, nearest, rtol=1e-9, atol=1e-12)) > 0.98
    # an affine motion of the nodes moves every vertex by the motion of its landing point
    a = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.0]])
    moved = w @ (nodes @ a.T + [0.1, 0.2, 0.3])
    np.testing.assert_allclose(moved, landing @ a.T + [0.1, 0.2, 0.3], atol=1e-12)
