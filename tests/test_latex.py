"""Latex hand puppets built from real meshes (pybullet's bunny and duck) and the shipped frog:
three layers, every node inside, positive tetrahedra, connection weights summing to one, rest
stays at rest, opening the glove opens the mouth, and clear errors for bad input."""
import json
import os

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from characters import ImplicitEuler, LatexPuppet, ProjectiveDynamics  # noqa: E402
from characters.latex import PD_ITERATIONS  # noqa: E402
from characters.latex.layers import tetrahedron_volumes  # noqa: E402
from characters.latex.surface import InsideTest, SurfaceDistance, signed_volume  # noqa: E402

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
DT = 1 / 25


def _pybullet(name):
    pybullet_data = pytest.importorskip("pybullet_data")
    return os.path.join(pybullet_data.getDataPath(), name)


@pytest.fixture(scope="module")
def froggy():
    return LatexPuppet.froggy(masses=600)


@pytest.fixture(scope="module")
def bunny():
    return LatexPuppet.from_mesh(_pybullet("bunny.obj"), masses=400)


@pytest.fixture(scope="module")
def duck():
    return LatexPuppet.from_mesh(_pybullet("duck.obj"), masses=800)


PUPPETS = [pytest.param("froggy"), pytest.param("bunny", marks=pytest.mark.realdata),
           pytest.param("duck", marks=pytest.mark.realdata)]


@pytest.fixture
def puppet(request):
    q = request.getfixturevalue(request.param)
    q.reset()
    yield q
    q.reset()


@pytest.mark.parametrize("puppet", PUPPETS, indirect=True)
@pytest.mark.slow
def test_three_layers_with_every_node_inside(puppet, rng):
    counts = np.bincount(puppet.layer, minlength=3)
    assert len(counts) == 3 and np.all(counts >= 4)
    assert 0.8 * puppet.report.layer_counts[0] <= counts[0]
    x = puppet.model.rest_positions
    visual = trimesh.Trimesh(puppet.rest_vertices, puppet.faces, process=False)
    # skin nodes are visual vertices, on the surface; the foam and cavity nodes are inside
    np.testing.assert_array_equal(x[puppet.layer == 0],
                                  puppet.rest_vertices[puppet.surface_visual_index])
    inner = x[puppet.layer > 0]
    assert np.all(InsideTest(puppet.rest_vertices, puppet.faces)(inner))
    # and by trimesh's ray test (slow on the frog's 40k faces: a sample of the nodes there)
    sample = inner if len(inner) <= 120 or len(puppet.faces) < 10000 else inner[
        rng.choice(len(inner), 60, replace=False)]
    assert np.all(visual.contains(sample))
    # the cavity lies deeper than the foam
    depth = SurfaceDistance(puppet.rest_vertices, puppet.faces)(x)
    assert np.median(depth[puppet.layer == 2]) > np.median(depth[puppet.layer == 1])
    assert set(np.unique(puppet.tetrahedron_layer)) >= {1}
    assert set(np.unique(puppet.model.springs.ravel())) == set(range(puppet.model.node_count))


@pytest.mark.parametrize("puppet", PUPPETS, indirect=True)
@pytest.mark.slow
def test_tetrahedra_have_positive_volume_and_fill_the_puppet(puppet):
    volume = tetrahedron_volumes(puppet.model.rest_positions, puppet.tetrahedra)
    assert volume.min() > 0
    share = volume.sum() / signed_volume(puppet.rest_vertices, puppet.faces)
    assert 0.5 < share <= 1.0 + 1e-9


@pytest.mark.parametrize("puppet", PUPPETS, indirect=True)
@pytest.mark.slow
def test_connection_weights_sum_to_one(puppet):
    w = puppet.connection.matrix()
    assert w.shape == (len(puppet.rest_vertices), int((puppet.layer == 0).sum()))
    np.testing.assert_allclose(np.asarray(w.sum(1)).ravel(), 1.0, rtol=1e-12)
    assert puppet.connection.weights.min() > 0


@pytest.mark.parametrize("puppet", PUPPETS, indirect=True)
@pytest.mark.slow
def test_a_puppet_at_rest_stays_at_rest(puppet):
    for _ in range(25):
        puppet.step(DT, {})
    scale = float(np.ptp(puppet.rest_vertices, axis=0).max())
    assert np.abs(puppet.state.x - puppet.model.rest_positions).max() < 1e-9 * scale
    assert np.abs(puppet.surface() - puppet.rest_vertices).max() < 1e-9 * scale
    assert puppet.integrator.last_report.ok


@pytest.fixture(params=["projective_dynamics", "implicit_euler"])
def integrator(request, froggy):
    """The frog stepped by each integrator (the test restores the default)."""
    default = froggy.integrator
    froggy.integrator = (ProjectiveDynamics(iterations=PD_ITERATIONS)
                         if request.param == "projective_dynamics"
                         else ImplicitEuler(tolerance=1e-3, max_iterations=200))
    yield request.param
    froggy.integrator = default
    froggy.reset()


@pytest.mark.slow
def test_opening_the_glove_opens_the_mouth(froggy, integrator):
    froggy.reset()
    closed = froggy.mouth_gap()
    gaps = []
    for bend in (0.5, 1.0):
        for _ in range(25):
            froggy.step(DT, {finger: bend for finger in FINGERS})
        gaps.append(froggy.mouth_gap())
    assert closed < gaps[0] < gaps[1]
    assert gaps[1] > closed + 0.03  # more than 3 cm wider open [m]
    # the visual mesh followed the nodes (equation 4): skin node vertices exactly
    skin = froggy.layer == 0
    np.testing.assert_allclose(froggy.surface()[froggy.surface_visual_index], froggy.state.x[skin],
                               atol=1e-12)
    # closing the hand again closes the mouth
    for _ in range(50):
        froggy.step(DT, {finger: 0.0 for finger in FINGERS})
    assert froggy.mouth_gap() == pytest.approx(closed, abs=0.005)
    assert froggy.integrator.last_report.ok and not froggy.integrator.last_report.retries


@pytest.mark.slow
def test_frog_at_rest_stays_at_rest_with_either_integrator(froggy, integrator):
    froggy.reset()
    for _ in range(10):
        froggy.step(DT, {})
    assert np.abs(froggy.state.x - froggy.model.rest_positions).max() < 1e-10


@pytest.mark.slow
def test_fingers_move_their_own_side_of_the_mouth(froggy):
    froggy.reset()
    upper, lower = froggy.landmark("upper_lip").copy(), froggy.landmark("lower_lip").copy()
    for _ in range(25):
        froggy.step(DT, {"thumb": 1.0})
    # the thumb is on the floor of the mouth: the lower lip drops more than the upper moves
    drop = lower[1] - froggy.landmark("lower_lip")[1]
    assert drop > 0.005
    assert np.linalg.norm(froggy.landmark("upper_lip") - upper) < drop


@pytest.mark.realdata
@pytest.mark.slow
def test_position_targets_pull_a_region_towards_them(bunny):
    bunny.reset()
    nodes = bunny.regions["index"]
    start = bunny.state.x[nodes].mean(0).copy()
    goal = start + np.array([0.0, 0.15, 0.0])
    for _ in range(30):
        bunny.step(DT, {"index": goal})
    reached = bunny.state.x[nodes].mean(0)
    assert np.linalg.norm(reached - goal) < 0.5 * np.linalg.norm(goal - start)
    bunny.reset()
    np.testing.assert_array_equal(bunny.state.x, bunny.model.rest_positions)
    np.testing.assert_array_equal(bunny.surface(), bunny.rest_vertices)


@pytest.mark.slow
def test_motion_channels_drive_the_fingers(froggy):
    from characters import Motion
    froggy.reset()
    motion = Motion({finger: (np.array([0.0, 1.0]), np.array([[0.0], [1.0]]))
                     for finger in FINGERS})
    closed = froggy.mouth_gap()
    for frame in range(25):
        froggy.step(DT, motion.sample(frame * DT))  # {finger: (1,) bend}
    assert froggy.mouth_gap() > closed + 0.03
    froggy.reset()


@pytest.mark.slow
def test_target_names_are_the_five_fingers_and_unknown_names_fail(froggy):
    assert froggy.target_names == FINGERS
    with pytest.raises(ValueError, match=r"unknown target 'elbow'.*\('thumb', 'index'"):
        froggy.step(DT, {"elbow": 1.0})
    with pytest.raises(ValueError, match="bend .* or a position"):
        froggy.step(DT, {"thumb": [1.0, 2.0]})
    with pytest.raises(ValueError, match="finite"):
        froggy.step(DT, {"thumb": float("nan")})
    with pytest.raises(ValueError, match="dt"):
        froggy.step(0.0, {})


@pytest.mark.slow
def test_froggy_regions_come_from_its_sidecar(froggy):
    sidecar = json.loads((LatexPuppet.froggy.__func__.__globals__["FROGGY"]).with_suffix(
        ".json").read_text())
    assert set(sidecar["regions"]) == set(FINGERS)
    for finger, nodes in froggy.regions.items():
        assert len(nodes) >= 3
        assert np.all(froggy.layer[nodes] == 0)
        visual = froggy.surface_visual_index[nodes]
        assert set(visual) <= set(sidecar["regions"][finger]["vertices"])
    assert froggy.vertex_colors is not None and froggy.vertex_colors.shape == (
        len(froggy.rest_vertices), 4)
    assert len(froggy.faces) > 20000


@pytest.mark.realdata
@pytest.mark.slow
def test_trimesh_object_and_path_build_the_same_puppet(bunny):
    mesh = trimesh.load(_pybullet("bunny.obj"), force="mesh")
    again = LatexPuppet.from_mesh(mesh, masses=400)
    np.testing.assert_allclose(again.model.rest_positions, bunny.model.rest_positions)
    np.testing.assert_array_equal(again.tetrahedra, bunny.tetrahedra)


@pytest.mark.realdata
@pytest.mark.slow
def test_stiffer_foam_opens_less(bunny):
    from characters.materials import material
    from dataclasses import replace
    stiff_foam = replace(material("latex_foam"), youngs_modulus=2.0e6)
    stiff = LatexPuppet.from_mesh(_pybullet("bunny.obj"), masses=400,
                                  materials={"foam": stiff_foam})
    # compared once both have settled (mean over frames 100-150): the stiff puppet rings for
    # about 4 s, and at frame 25 the two spreads were within 0.02 % of each other
    spread = []
    for q in (bunny, stiff):
        q.reset()
        widths = []
        for frame in range(150):
            q.step(DT, {finger: 1.0 for finger in FINGERS})
            if frame >= 100:
                widths.append(np.ptp(q.surface()[:, 1]))
        spread.append(np.mean(widths))
    assert spread[1] < spread[0] - 0.003
    bunny.reset()


# --- bad input ------------------------------------------------------------------------------------

def test_open_mesh_is_rejected_naming_its_holes():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    centroids = sphere.vertices[sphere.faces].mean(1)
    open_mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[centroids[:, 1] < 0.8],
                                process=False)
    with pytest.raises(ValueError, match=r"open and could not be closed: \d+ boundary edges in 1 "
                                         r"loop"):
        LatexPuppet.from_mesh(open_mesh, masses=200)


def test_too_few_masses_is_explained():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    with pytest.raises(ValueError, match="masses=20 is too small for three closed layers"):
        LatexPuppet.from_mesh(sphere, masses=20)
    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.03)).subdivide().subdivide().subdivide()
    with pytest.raises(ValueError, match="too few nodes for three layers.*too thin"):
        LatexPuppet.from_mesh(plate, masses=150)


def test_finger_region_outside_the_mesh_is_rejected():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    regions = {"thumb": {"center": [0.0, -1.0, 0.0], "radius": 0.2},
               "index": {"center": [0.0, 3.0, 0.0], "radius": 0.2}}
    with pytest.raises(ValueError, match=r"finger region 'index' lies outside the mesh: its "
                                         r"centre \[0.0, 3.0, 0.0\] is 2 m"):
        LatexPuppet.from_mesh(sphere, masses=300, finger_regions=regions)
    with pytest.raises(ValueError, match="finger region 'thumb' lies outside the mesh: vertex "
                                         "9999 does not exist"):
        LatexPuppet.from_mesh(sphere, masses=300, finger_regions={"thumb": [1, 9999]})


def test_finger_region_that_would_be_lost_is_rejected():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    # a region made only of a vertex no face uses: cleaning drops it, so would decimation
    vertices = np.concatenate([sphere.vertices, [[0.0, 0.0, 0.0]]])
    mesh = trimesh.Trimesh(vertices, sphere.faces, process=False)
    lonely = len(vertices) - 1
    with pytest.raises(ValueError, match="finger region 'thumb' would be lost: all 1 of its"):
        LatexPuppet.from_mesh(mesh, masses=300, finger_regions={"thumb": [lonely]})
    between = sphere.vertices[sphere.faces[0]].mean(0)  # on a face, away from its corners
    with pytest.raises(ValueError, match="would be lost: no vertex lies within"):
        LatexPuppet.from_mesh(mesh, masses=300, finger_regions={
            "thumb": {"center": between.tolist(), "radius": 1e-3}})


def test_overlapping_or_scattered_regions_are_rejected():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    top = int(np.argmax(sphere.vertices[:, 1]))
    bottom = int(np.argmin(sphere.vertices[:, 1]))
    with pytest.raises(ValueError, match="'thumb' and 'index' overlap in 1 vertices"):
        LatexPuppet.from_mesh(sphere, masses=300, finger_regions={"thumb": [top],
                                                                   "index": [top]})
    with pytest.raises(ValueError, match="not made of adjacent vertices: .* 2 separate pieces"):
        LatexPuppet.from_mesh(sphere, masses=300, finger_regions={"thumb": [top, bottom]})


def test_unknown_material_and_integrator_are_rejected():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    with pytest.raises(ValueError, match="unknown material 'jelly'"):
        LatexPuppet.from_mesh(sphere, masses=300, materials={"foam": "jelly"})
    with pytest.raises(ValueError, match="needs volumetric presets|no youngs_modulus"):
        LatexPuppet.from_mesh(sphere, masses=300, materials=("skin", "latex_foam", "latex_cavity"))
    with pytest.raises(ValueError, match="integrator must be one of"):
        LatexPuppet.from_mesh(sphere, masses=300, integrator="euler")
