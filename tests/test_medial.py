"""Medial objects: building from real third-party meshes (pybullet's duck and bunny), the
skeleton, bone points, joints geometry and bad input. Dynamics are in test_medial_dynamics.py."""
import json
import math
import os

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pybullet_data = pytest.importorskip("pybullet_data")

from characters.medial import MedialObject  # noqa: E402
from characters.medial import joints as joint_kernels  # noqa: E402
from characters.medial import mesh_input, skeleton as skeleton_kernels  # noqa: E402
from characters.medial.joints import JointCut, JointSpec  # noqa: E402

DATA = pybullet_data.getDataPath()
BUNNY_CUT = dict(section="body", names=["bottom", "top"], point=[0.0, 0.0, 0.2],
                 normal=[0.0, 0.0, 1.0], axis=[1.0, 0.0, 0.0])


def real_mesh(name):
    return os.path.join(DATA, name)


@pytest.fixture(scope="module")
def duck():
    return MedialObject.from_mesh(real_mesh("duck.obj"), material="water")


@pytest.fixture(scope="module")
def bunny():
    return MedialObject.from_mesh(real_mesh("bunny.obj"), material="thick skin",
                                  joints=[BUNNY_CUT])


@pytest.fixture(scope="module", params=["duck", "bunny"])
def real(request, duck, bunny):
    return {"duck": duck, "bunny": bunny}[request.param]


# --- skeleton ------------------------------------------------------------------------------------

@pytest.mark.realdata
@pytest.mark.slow
def test_one_skeletal_point_per_vertex_same_connectivity(real):
    vertex_count = len(real.rest_vertices)
    assert real.skeleton.shape == (vertex_count, 3)
    assert np.all(np.isfinite(real.skeleton))
    # the skeletal mesh uses the surface's faces: same connectivity, one point per vertex
    np.testing.assert_array_equal(real.faces, real.mesh.faces)
    assert real.faces.max() == vertex_count - 1
    # s = p - d n: on the negative vertex normal at the recorded depth
    normals = np.asarray(real.mesh.vertex_normals)
    np.testing.assert_allclose(real.skeleton,
                               real.rest_vertices - real.skeleton_info.depth[:, None] * normals,
                               atol=1e-12)


@pytest.mark.realdata
@pytest.mark.slow
def test_vertex_count_is_that_of_the_closed_surface():
    # OBJ texture seams split vertices; the medial object works on the welded surface
    raw = trimesh.load(real_mesh("duck.obj"), force="mesh")
    welded = raw.copy()
    welded.merge_vertices(merge_tex=True, merge_norm=True)
    assert len(raw.vertices) > len(welded.vertices)
    repaired = mesh_input.load_closed_mesh(real_mesh("duck.obj"))
    assert len(repaired.vertices) == len(welded.vertices)
    assert repaired.is_watertight and repaired.is_volume


@pytest.mark.realdata
@pytest.mark.slow
def test_skeletal_points_inside_the_surface(real):
    info = real.skeleton_info
    edge = float(real.mesh.edges_unique_length.mean())
    deep = info.depth > 0.01 * edge
    # the paper's fallback (the surface point itself) is rare on these meshes
    assert info.fallback.mean() < 0.05
    assert deep.mean() > 0.9
    assert real.mesh.contains(real.skeleton[deep]).all()
    # the shallow ones are not outside either (contains() is unreliable that close)
    signed = trimesh.proximity.ProximityQuery(real.mesh).signed_distance(real.skeleton[~deep])
    assert np.all(signed > -1e-9)


@pytest.mark.slow
def test_internal_voronoi_points_match_slow_reference(bunny):
    mesh = bunny.mesh
    points = np.asarray(mesh.vertices)
    owner, corner, voronoi_points = skeleton_kernels.voronoi_cell_pairs(points)
    args = (points, np.asarray(mesh.face_normals), np.asarray(mesh.vertex_faces), owner,
            voronoi_points[corner])
    fast = skeleton_kernels.internal_voronoi_mask(*args)
    slow = skeleton_kernels.internal_voronoi_mask_reference(*args)
    np.testing.assert_array_equal(fast, slow)
    assert 0.05 < fast.mean() < 0.95   # a real partition, not all or nothing


@pytest.mark.realdata
@pytest.mark.slow
def test_inner_chords_grid_matches_brute_force(duck):
    mesh = duck.mesh
    points, normals = np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals)
    min_hit = 1e-3 * float(mesh.edges_unique_length.mean())
    fast = skeleton_kernels.inner_chord_lengths(points, normals, mesh.triangles, min_hit=min_hit)
    slow = skeleton_kernels.first_hits_reference(points, -normals, np.asarray(mesh.triangles),
                                                 min_hit)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    assert np.all(np.isfinite(fast))
    # depth never exceeds half the chord: a medial ball tangent at p cannot reach past it
    assert np.all(duck.skeleton_info.depth <= 0.5 * fast + 1e-12)


def capsule(radius=0.2, half_length=0.5, edge=0.05):
    manifold3d = pytest.importorskip("manifold3d")

    def sdf(x, y, z):
        zc = min(max(z, -half_length), half_length)
        return radius - math.sqrt(x * x + y * y + (z - zc) ** 2)

    extent = radius + 0.1
    solid = manifold3d.Manifold.level_set(
        sdf, [-extent, -extent, -half_length - extent, extent, extent, half_length + extent],
        edge, 0.0, 0.02 * edge).to_mesh()
    return trimesh.Trimesh(solid.vert_properties[:, :3], solid.tri_verts)


@pytest.mark.slow
def test_capsule_skeleton_lies_near_its_axis():
    # analytic medial axis of a capsule: the segment; every medial ball has the radius
    radius = 0.2
    obj = MedialObject.from_mesh(capsule(radius), material="skin")
    z = obj.rest_vertices[:, 2]
    cylinder = np.abs(z) < 0.4
    depth = obj.skeleton_info.depth[cylinder]
    # the paper averages all internal Voronoi points, which pulls towards the surface a little
    assert depth.max() <= radius * 1.001
    assert depth.min() > 0.5 * radius
    assert np.median(depth) > 0.8 * radius
    off_axis = np.linalg.norm(obj.skeleton[cylinder, :2], axis=1)
    assert off_axis.max() < 0.5 * radius


def test_bone_points_reflect_through_the_surface(bunny):
    vertex_count = bunny.vertex_count
    x = bunny.model.rest_positions
    surface, inner, outer = (x[:vertex_count], x[vertex_count:2 * vertex_count],
                             x[2 * vertex_count:])
    np.testing.assert_allclose(inner + outer, 2.0 * surface, atol=1e-12)
    fbd = bunny.material.bone_distance
    np.testing.assert_allclose(np.linalg.norm(inner - surface, axis=1),
                               fbd * bunny.skeleton_info.depth, atol=1e-12)
    # inner bone point on the segment from the surface to the skeletal point
    np.testing.assert_allclose(inner, surface + fbd * (bunny.skeleton - surface), atol=1e-12)
    # springs: every mesh edge, plus two bone springs per dynamic vertex, bones fixed
    dynamic = bunny.dynamic_vertices
    assert bunny.model.spring_count == len(bunny.mesh.edges_unique) + 2 * len(dynamic)
    assert bunny.model.fixed[vertex_count:].all()
    assert not bunny.model.fixed[dynamic].any()
    np.testing.assert_allclose(bunny.model.rest_length[bunny.bone_spring_index],
                               np.tile(bunny.bone_rest_length[dynamic], 2))


def test_material_thickness_scales_bone_springs(bunny):
    thin = MedialObject.from_mesh(bunny.mesh, material="skin", joints=[BUNNY_CUT])
    # same skeleton, bone distance 0.2 instead of 0.5: every bone spring 0.4 x as long
    np.testing.assert_allclose(thin.skeleton, bunny.skeleton)
    np.testing.assert_allclose(thin.bone_rest_length, 0.4 * bunny.bone_rest_length)
    plastic = MedialObject.from_mesh(bunny.mesh, material="plastic")
    assert plastic.material.rigid
    assert len(plastic.dynamic_vertices) == 0 and plastic.model.fixed.all()


# --- self-intersections --------------------------------------------------------------------------

def crossing_pairs_reference(vertices, faces):
    """Every face pair (no shared vertex) tested with the same segment test, no broad phase."""
    test = mesh_input._segment_hits_triangle.py_func
    found = set()
    for i in range(len(faces)):
        for j in range(i + 1, len(faces)):
            if set(faces[i]) & set(faces[j]):
                continue
            hit = False
            for first, second in ((i, j), (j, i)):
                a, b, c = vertices[faces[second]]
                for e in range(3):
                    if test(vertices[faces[first][e]], vertices[faces[first][(e + 1) % 3]],
                            a, b, c, 1e-9):
                        hit = True
            if hit:
                found.add((i, j))
    return found


def two_overlapping_spheres(subdivisions=1):
    a = trimesh.creation.icosphere(subdivisions)
    b = a.copy()
    b.apply_translation([0.9, 0.1, 0.05])
    return trimesh.util.concatenate([a, b])


@pytest.mark.slow
def test_self_intersection_sweep_matches_all_pairs():
    mesh = two_overlapping_spheres(1)
    fast = {tuple(p) for p in mesh_input.self_intersections(mesh.vertices, mesh.faces)}
    slow = crossing_pairs_reference(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    assert fast == slow and len(fast) > 10


@pytest.mark.realdata
@pytest.mark.slow
def test_duck_small_self_intersection_is_repaired():
    raw = trimesh.load(real_mesh("duck.obj"), force="mesh")
    raw.merge_vertices(merge_tex=True, merge_norm=True)
    assert len(mesh_input.self_intersections(raw.vertices, raw.faces)) > 0
    repaired = mesh_input.load_closed_mesh(real_mesh("duck.obj"))
    assert len(mesh_input.self_intersections(repaired.vertices, repaired.faces)) == 0
    moved = np.linalg.norm(repaired.vertices - raw.vertices, axis=1)
    edge = float(raw.edges_unique_length.mean())
    assert 1 <= np.count_nonzero(moved) <= 3
    assert moved.max() < mesh_input.SMALL_INTERSECTION * edge


# --- joints geometry -----------------------------------------------------------------------------

def test_rotation_matrix_matches_scipy(rng):
    from scipy.spatial.transform import Rotation

    for _ in range(20):
        vector = rng.normal(size=3)
        np.testing.assert_allclose(joint_kernels.rotation_matrix(vector),
                                   Rotation.from_rotvec(vector).as_matrix(), atol=1e-12)


def test_section_transforms_compose_like_forward_kinematics(rng):
    parent = np.array([-1, 0, 0, 2, 2, 3, 3])
    pivot = rng.normal(size=(7, 3))
    vectors = rng.normal(size=(7, 3))
    vectors[0] = 0.0
    tree = joint_kernels.JointTree(names=tuple("abcdefg"), parent=parent,
                                   children=np.full((7, 2), -1), pivot=pivot,
                                   axis=np.zeros((7, 3)), section_of_vertex=np.zeros(0, int))
    rotations, translations = np.empty((7, 3, 3)), np.empty((7, 3))
    joint_kernels.section_transforms(tree, vectors, rotations, translations)
    point = rng.normal(size=3)
    for leaf in (1, 4, 5, 6):
        # slow: apply each ancestor's rotation about its pivot, innermost first
        chain, node = [], leaf
        while node > 0:
            chain.append(node)
            node = parent[node]
        expected = point.copy()
        for node in chain:
            r = joint_kernels.rotation_matrix(vectors[node])
            expected = r @ (expected - pivot[node]) + pivot[node]
        np.testing.assert_allclose(rotations[leaf] @ point + translations[leaf], expected,
                                   atol=1e-12)


def test_sections_split_by_skeletal_points(bunny):
    tree = bunny.joints
    assert tree.names == ("body", "bottom", "top")
    assert bunny.target_names == ("bottom", "top")
    top = tree.vertices_of("top")
    bottom = tree.vertices_of("bottom")
    assert len(top) + len(bottom) == bunny.vertex_count
    assert np.all(bunny.skeleton[top, 2] > 0.2) and np.all(bunny.skeleton[bottom, 2] <= 0.2)
    np.testing.assert_array_equal(np.sort(tree.vertices_of("body")), np.arange(bunny.vertex_count))
    # the default pivot is on the plane, inside the object's skeleton span
    pivot = tree.pivot[tree.names.index("top")]
    assert pivot[2] == pytest.approx(0.2)
    assert bunny.mesh.contains(pivot[None])[0]


def test_posed_rest_rotates_a_section_about_its_pivot(bunny):
    angle = 0.7
    posed = bunny.posed_rest({"top": angle})
    tree = bunny.joints
    index = tree.names.index("top")
    rotation = joint_kernels.rotation_matrix(angle * tree.axis[index])
    pivot = tree.pivot[index]
    top, bottom = tree.vertices_of("top"), tree.vertices_of("bottom")
    np.testing.assert_allclose(posed[top], (bunny.rest_vertices[top] - pivot) @ rotation.T + pivot,
                               atol=1e-12)
    np.testing.assert_array_equal(posed[bottom], bunny.rest_vertices[bottom])
    # a rotation vector works too and a scalar is about the cut's axis
    np.testing.assert_allclose(bunny.posed_rest({"top": angle * tree.axis[index]}), posed)


def test_joint_spec_json_round_trip(tmp_path):
    spec = JointSpec(root="whole", cuts=(
        JointCut(section="whole", names=("a", "b"), point=(0, 0, 0.1), normal=(0, 0, 2),
                 axis=(1, 0, 0), pivot=(0.0, 0.0, 0.1)),
        JointCut(section="b", names=("c", "d"), point=(0, 0.3, 0), normal=(0, 1, 0),
                 axis=(0, 0, 1))), extras={"motion": "x.motion.json"})
    path = tmp_path / "thing.joints.json"
    spec.save(path)
    loaded = JointSpec.load(path)
    assert loaded.to_dict() == JointSpec.from_dict(json.loads(path.read_text())).to_dict()
    assert loaded.root == "whole" and [c.names for c in loaded.cuts] == [("a", "b"), ("c", "d")]
    assert loaded.cuts[1].pivot is None
    assert loaded.extras == {"motion": "x.motion.json"}


# --- the shipped creature ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def creature():
    return MedialObject.shipped("medial_caterpillar")


@pytest.mark.slow
def test_shipped_creature_has_its_joint_tree(creature):
    assert creature.target_names == ("tail", "front", "chest", "head", "skull", "jaw")
    tree = creature.joints
    # binary tree: every cut section has exactly two children; leaves partition the vertices
    for index, _name in enumerate(tree.names):
        children = tree.children[index]
        assert (children >= 0).sum() in (0, 2)
    leaves = {tree.names[s] for s in np.unique(tree.section_of_vertex)}
    assert leaves == {"tail", "chest", "skull", "jaw"}
    # every motion channel of the shipped clip addresses a section
    from characters import Motion
    folder = os.path.dirname(creature_path())
    motion = Motion.load(os.path.join(folder, "medial_caterpillar.motion.json"))
    assert set(motion.channel_names) <= set(creature.target_names)
    assert creature.mesh.is_volume
    assert creature.skeleton_info.fallback.sum() == 0


def creature_path():
    import characters
    return os.path.join(os.path.dirname(characters.__file__), "assets", "medial_caterpillar.obj")


@pytest.mark.slow
def test_shipped_creature_regenerates_identically(tmp_path):
    from characters.assets import caterpillar as builder

    paths = builder.write_assets(tmp_path)
    shipped = os.path.dirname(creature_path())
    for path in paths[1:]:   # joints and motion: byte for byte
        with open(path, "rb") as new, open(os.path.join(shipped, path.name), "rb") as old:
            assert new.read() == old.read(), path.name
    # the surface: same shape (a threaded mesher may order vertices differently)
    new = trimesh.load(paths[0], force="mesh", process=False)
    old = trimesh.load(creature_path(), force="mesh", process=False)
    assert new.vertices.shape == old.vertices.shape and new.faces.shape == old.faces.shape
    np.testing.assert_allclose(np.sort(new.vertices, axis=0), np.sort(old.vertices, axis=0),
                               atol=1e-6)
    assert new.volume == pytest.approx(old.volume, rel=1e-6)


# --- bad input -----------------------------------------------------------------------------------

def test_open_mesh_is_refused():
    sphere = trimesh.creation.icosphere(2)
    sphere.update_faces(np.arange(len(sphere.faces) - 3))
    with pytest.raises(ValueError, match="not a closed surface: .* boundary edges"):
        MedialObject.from_mesh(sphere)


def test_non_manifold_mesh_is_refused():
    # two boxes touching along one edge: that edge joins four faces
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[1, 1, 0], [2, 2, 1]])
    with pytest.raises(ValueError, match="not a manifold surface: 1 edges are shared by more"):
        MedialObject.from_mesh(trimesh.util.concatenate([a, b]))


def test_inconsistent_winding_is_refused():
    sphere = trimesh.creation.icosphere(2)
    faces = sphere.faces.copy()
    faces[0] = faces[0][::-1]
    with pytest.raises(ValueError, match="inconsistent face winding"):
        MedialObject.from_mesh(trimesh.Trimesh(sphere.vertices, faces, process=False))


def test_inside_out_mesh_is_repaired():
    sphere = trimesh.creation.icosphere(2)
    inverted = trimesh.Trimesh(sphere.vertices, sphere.faces[:, ::-1], process=False)
    obj = MedialObject.from_mesh(inverted)
    assert obj.mesh.volume > 0
    assert np.all(np.linalg.norm(obj.skeleton, axis=1) < 0.5)   # inside, not mirrored outside


def test_too_coarse_mesh_is_refused():
    with pytest.raises(ValueError, match="too coarse: 8 vertices"):
        MedialObject.from_mesh(trimesh.creation.box())


@pytest.mark.slow
def test_mesh_too_coarse_for_its_curvature_is_refused_and_subdividing_helps():
    # a cone is only its rim, apex and base centre: no internal Voronoi point for most vertices
    cone = trimesh.creation.cone(radius=0.5, height=1.0, sections=32)
    with pytest.raises(ValueError, match="too coarse for its curvature: 97% of its 34 vertices"):
        MedialObject.from_mesh(cone)
    vertices, faces = trimesh.remesh.subdivide_to_size(cone.vertices, cone.faces, 0.1)
    obj = MedialObject.from_mesh(trimesh.Trimesh(vertices, faces))
    assert obj.skeleton_info.fallback.mean() < 0.05


def test_self_intersecting_mesh_is_refused():
    with pytest.raises(ValueError, match="intersects itself: .* pairs of faces cross"):
        MedialObject.from_mesh(two_overlapping_spheres(2))


def test_wrong_types_and_names_are_refused(bunny):
    with pytest.raises(TypeError, match="path or a trimesh.Trimesh, got ndarray"):
        MedialObject.from_mesh(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="unknown medial material 'jelly'"):
        MedialObject.from_mesh(bunny.mesh, material="jelly")
    with pytest.raises(ValueError, match="not a medial-object material"):
        MedialObject.from_mesh(bunny.mesh, material=__import__("characters").material("rubber"))
    with pytest.raises(ValueError, match="constraint must be one of"):
        MedialObject.from_mesh(bunny.mesh, constraint="glue")
    with pytest.raises(ValueError, match="max_factor must be >= 1"):
        MedialObject.from_mesh(bunny.mesh, f_max=0.9)


def cut(**changes):
    return [{**BUNNY_CUT, **changes}]


def test_cutting_plane_that_misses_is_refused(bunny):
    with pytest.raises(ValueError, match="misses section 'body'"):
        MedialObject.from_mesh(bunny.mesh, joints=cut(point=[0.0, 0.0, 5.0]))


def test_pivot_far_from_the_plane_is_refused(bunny):
    with pytest.raises(ValueError, match="pivot .* from the cutting plane"):
        MedialObject.from_mesh(bunny.mesh, joints=cut(pivot=[0.0, 0.0, 0.9]))
    with pytest.raises(ValueError, match="far outside section 'body'"):
        MedialObject.from_mesh(bunny.mesh, joints=cut(pivot=[30.0, 0.0, 0.2]))


def test_bad_joint_trees_are_refused(bunny):
    with pytest.raises(ValueError, match="no section named 'head'"):
        MedialObject.from_mesh(bunny.mesh, joints=cut(section="head"))
    second = {**BUNNY_CUT, "names": ["x", "y"], "point": [0, 0, 0.5]}
    with pytest.raises(ValueError, match="'body' is already cut in two"):
        MedialObject.from_mesh(bunny.mesh, joints=cut() + [second])
    with pytest.raises(ValueError, match="'top' is already used"):
        MedialObject.from_mesh(bunny.mesh, joints=cut() + [
            {**second, "section": "top", "names": ["top", "y"]}])
    with pytest.raises(ValueError, match="missing \\['axis'\\]"):
        MedialObject.from_mesh(bunny.mesh, joints=[{k: v for k, v in BUNNY_CUT.items()
                                                   if k != "axis"}])
    with pytest.raises(ValueError, match="normal must be a non-zero vector"):
        MedialObject.from_mesh(bunny.mesh, joints=cut(normal=[0, 0, 0]))


def test_bad_joint_files_are_refused(tmp_path, bunny):
    path = tmp_path / "bad.joints.json"
    path.write_text('{"format": "something/2", "cuts": []}')
    with pytest.raises(ValueError, match="format must be 'mop.medial_joints/1'"):
        MedialObject.from_mesh(bunny.mesh, joints=path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        MedialObject.from_mesh(bunny.mesh, joints=path)


def test_bad_targets_are_refused(bunny):
    with pytest.raises(ValueError, match=r"unknown target 'ears'.*\['bottom', 'top'\]"):
        bunny.step(0.04, {"ears": 0.1})
    with pytest.raises(ValueError, match="angle must be finite"):
        bunny.step(0.04, {"top": float("nan")})
    with pytest.raises(ValueError, match="expected an angle .* got 2 values"):
        bunny.step(0.04, {"top": [0.1, 0.2]})
    with pytest.raises(ValueError, match="dt must be a finite time step"):
        bunny.step(0.0, {})
    with pytest.raises(TypeError, match="targets must be a mapping"):
        bunny.step(0.04, [0.1])
    bunny.reset()
