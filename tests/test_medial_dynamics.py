"""Medial objects in motion: constraints under violent input, the five material presets,
joints dragging the surface, the fold on the inner side, and the puppet interface."""
import os

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
pybullet_data = pytest.importorskip("pybullet_data")

from characters import Motion  # noqa: E402
from characters.medial import MedialObject  # noqa: E402

BUNNY = os.path.join(pybullet_data.getDataPath(), "bunny.obj")
BUNNY_CUT = dict(section="body", names=["bottom", "top"], point=[0.0, 0.0, 0.2],
                 normal=[0.0, 0.0, 1.0], axis=[1.0, 0.0, 0.0])
PRESETS = ("thick skin", "water", "plastic", "skin", "tight cloth")


@pytest.fixture(scope="module")
def bunny_mesh():
    from characters.medial.mesh_input import load_closed_mesh
    return load_closed_mesh(BUNNY)


def region_violation(obj, centres):
    """Largest violation of each dynamic mass point's allowed region, relative to L.

    centres : (V, 3) the posed rest positions (where the bones say each vertex belongs)."""
    dyn = obj.dynamic_vertices
    count = obj.vertex_count
    x = obj.state.x
    length = obj.bone_rest_length[dyn]
    f = obj.material
    if obj.constraint.value == "circumsphere":
        radius = (f.max_factor - 1.0) * length
        return float(np.max(np.linalg.norm(x[dyn] - centres[dyn], axis=1) - radius) / length.min())
    inner = np.linalg.norm(x[dyn] - x[count + dyn], axis=1) / length
    outer = np.linalg.norm(x[dyn] - x[2 * count + dyn], axis=1) / length
    return float(max(np.max(np.maximum(inner, outer)) - f.max_factor,
                     f.min_factor - np.min(np.minimum(inner, outer))))


@pytest.mark.realdata
@pytest.mark.parametrize("constraint", ["circumsphere", "spring_reduction"])
@pytest.mark.slow
def test_constraint_keeps_every_mass_point_in_its_region(constraint, bunny_mesh, rng):
    """10^4 steps of violent input: the joint flung to random orientations every step, every
    mass point kicked with random velocities and displacements as large as the object."""
    obj = MedialObject.from_mesh(bunny_mesh, material="water", constraint=constraint,
                                 joints=[BUNNY_CUT], check_self_intersections=False)
    dyn = obj.dynamic_vertices
    size = float(np.linalg.norm(np.ptp(obj.rest_vertices, axis=0)))
    bound = np.sqrt(obj.material.max_factor ** 2 - 1.0) * obj.bone_rest_length
    worst = -np.inf
    farthest = 0.0
    for _ in range(10_000):
        pose = {"top": rng.uniform(-np.pi, np.pi, size=3)}
        obj.state.v[dyn] += rng.normal(scale=20.0 * size, size=(len(dyn), 3))
        obj.state.x[dyn] += rng.normal(scale=0.5 * size, size=(len(dyn), 3))
        obj.step(0.01, pose)      # one Verlet substep per step: 10^4 constrained substeps
        centres = obj.posed_rest(pose)
        worst = max(worst, region_violation(obj, centres))
        away = np.linalg.norm(obj.surface() - centres, axis=1)
        farthest = max(farthest, float(np.max(away[dyn] / bound[dyn])))
        # vertices without bone length are carried exactly
        assert np.all(away[obj.kinematic_vertices] <= 1e-12)
    assert np.all(np.isfinite(obj.state.x)) and np.all(np.isfinite(obj.state.v))
    tolerance = 1e-9 if constraint == "circumsphere" else 1e-6   # iterated: converges, not exact
    assert worst <= tolerance
    # either region lies within sqrt(f_max^2 - 1) L of the posed rest position
    assert farthest <= 1.0 + 1e-6
    # and the input really was violent: points were driven to the edge of their regions
    assert worst > -0.05


@pytest.fixture(scope="module")
def material_runs(bunny_mesh):
    """Each preset: the top of the bunny flung by 0.5 rad in one 20 ms step and held for 8 s."""
    dt, seconds = 0.02, 8.0
    runs = {}
    for name in PRESETS:
        obj = MedialObject.from_mesh(bunny_mesh, material=name, joints=[BUNNY_CUT],
                                     check_self_intersections=False)
        pose = {"top": 0.5}
        posed = obj.posed_rest(pose)
        top = obj.joints.vertices_of("top")
        previous = obj.surface()
        speed, deviation, sway = [], [], []
        for _ in range(int(round(seconds / dt))):
            obj.step(dt, pose)
            now = obj.surface()
            speed.append(np.sqrt(np.mean(np.sum((now - previous) ** 2, axis=1))) / dt)
            deviation.append(np.max(np.abs(now - posed)))
            sway.append((now[top] - posed[top]).mean(axis=0))
            previous = now
        speed = np.array(speed[1:])            # the first step carries the rigid swing itself
        peak = speed.max()
        settle = (np.flatnonzero(speed > 0.01 * peak)[-1] + 2) * dt if peak > 0 else 0.0
        sway = np.array(sway)[:, 1]
        sway = sway - sway[-1]
        spectrum = np.abs(np.fft.rfft(sway - sway.mean()))
        frequency = np.fft.rfftfreq(len(sway), dt)[1 + np.argmax(spectrum[1:])]
        runs[name] = dict(settle=settle, deviation=max(deviation), peak_speed=peak,
                          frequency=frequency, length=float(np.median(obj.bone_rest_length)))
    return runs


@pytest.mark.realdata
@pytest.mark.slow
def test_water_wobbles_longest(material_runs):
    water = material_runs["water"]["settle"]
    others = [material_runs[n]["settle"] for n in PRESETS if n != "water"]
    assert water > 2.5 * max(others)


@pytest.mark.realdata
@pytest.mark.slow
def test_plastic_does_not_deform(material_runs):
    plastic = material_runs["plastic"]
    assert plastic["deviation"] == 0.0      # exactly the rigidly rotated rest shape, always
    assert plastic["peak_speed"] == 0.0     # nothing moves once the bones stop
    for name in PRESETS:
        if name != "plastic":
            assert material_runs[name]["deviation"] > 1e-3


@pytest.mark.realdata
@pytest.mark.slow
def test_thick_skin_is_damped_fastest_and_skin_is_firmest(material_runs):
    dynamic = [n for n in PRESETS if n != "plastic"]
    # C_vd 0.7: the most damped of Table 1
    assert material_runs["thick skin"]["settle"] == min(material_runs[n]["settle"] for n in dynamic)
    # skin's bones are nearest the surface (d_B 0.2): the least deformation
    assert material_runs["skin"]["deviation"] == min(material_runs[n]["deviation"] for n in dynamic)
    assert material_runs["skin"]["length"] < material_runs["thick skin"]["length"]


@pytest.mark.realdata
@pytest.mark.slow
def test_tight_cloth_sways_slowest(material_runs):
    # D 0.2 against 1.0: the softest springs, the lowest sway frequency
    cloth = material_runs["tight cloth"]["frequency"]
    for name in ("thick skin", "water", "skin"):
        assert cloth < 0.7 * material_runs[name]["frequency"]


@pytest.mark.realdata
@pytest.mark.parametrize("constraint", ["circumsphere", "spring_reduction"])
def test_rotated_section_drags_the_surface_and_the_other_stays(constraint, bunny_mesh):
    obj = MedialObject.from_mesh(bunny_mesh, material="skin", constraint=constraint,
                                 joints=[BUNNY_CUT], check_self_intersections=False)
    pose = {"top": 0.6}
    for _ in range(50):
        obj.step(0.04, pose)
    tree = obj.joints
    top, bottom = tree.vertices_of("top"), tree.vertices_of("bottom")
    now, rest, posed = obj.surface(), obj.rest_vertices, obj.posed_rest(pose)
    bound = np.sqrt(obj.material.max_factor ** 2 - 1.0) * obj.bone_rest_length
    moved = np.linalg.norm(now - rest, axis=1)
    # the rotated section came along: it sits at its rigidly rotated place, to within its region
    assert np.all(np.linalg.norm(now[top] - posed[top], axis=1) <= bound[top] + 1e-9)
    assert np.median(moved[top]) > 5.0 * np.median(bound[top])
    # the other section stayed put, to within its region
    assert np.all(moved[bottom] <= bound[bottom] + 1e-9)
    # and the surface is still elastic there: some of it moves, dragged by the joint
    assert moved[bottom].max() > 0.1 * bound[bottom].max()
    # back to angle 0 when the target is released
    for _ in range(100):
        obj.step(0.04, {})
    assert np.max(np.linalg.norm(obj.surface() - rest, axis=1) - bound) <= 1e-9


@pytest.fixture(scope="module")
def creature_mesh():
    from characters.assets.caterpillar import caterpillar_joints
    obj = MedialObject.shipped("medial_caterpillar")
    return obj.mesh, caterpillar_joints()


@pytest.mark.parametrize("angle,inner", [(0.5, "top"), (-0.5, "bottom")])
@pytest.mark.slow
def test_fold_on_the_inner_side_of_the_joint(angle, inner, creature_mesh):
    mesh, joints = creature_mesh
    obj = MedialObject.from_mesh(mesh, material="skin", constraint="spring_reduction",
                                 joints=joints, check_self_intersections=False)
    for _ in range(50):
        obj.step(0.04, {"front": angle})
    tree, faces = obj.joints, obj.faces
    moving = tree.descendants_mask(tree.names.index("front"))[tree.section_of_vertex]
    spanning = moving[faces].any(axis=1) & ~moving[faces].all(axis=1)

    def normals(v):
        t = v[faces]
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    rest_n, now_n = normals(obj.rest_vertices), normals(obj.surface())
    # signed area ratio against the rest orientation: < 0 where the surface has folded over
    signed = np.einsum("ij,ij->i", now_n, rest_n) / np.einsum("ij,ij->i", rest_n, rest_n)
    upper = obj.rest_vertices[faces].mean(axis=1)[:, 1] > 0.05   # y is up
    side = {"top": spanning & upper, "bottom": spanning & ~upper}
    outer = "bottom" if inner == "top" else "top"
    assert side[inner].sum() > 10 and side[outer].sum() > 10
    assert np.median(signed[side[inner]]) < 0.0      # folded on the inner side
    assert np.median(signed[side[outer]]) > 1.0      # stretched on the outer side


@pytest.mark.slow
def test_several_sections_at_once_follow_their_chain(creature_mesh):
    mesh, joints = creature_mesh
    obj = MedialObject.from_mesh(mesh, material="skin", joints=joints,
                                 check_self_intersections=False)
    pose = {"jaw": 0.4, "head": 0.3, "front": 0.2, "tail": 0.25}
    for _ in range(40):
        obj.step(0.04, pose)
    posed = obj.posed_rest(pose)
    bound = np.sqrt(obj.material.max_factor ** 2 - 1.0) * obj.bone_rest_length
    now = obj.surface()
    assert np.all(np.linalg.norm(now - posed, axis=1) <= bound + 1e-9)
    # the jaw went with the head, the front and its own hinge: farther than the skull
    tree = obj.joints
    moved = np.linalg.norm(now - obj.rest_vertices, axis=1)
    jaw, skull = tree.vertices_of("jaw"), tree.vertices_of("skull")
    jaw_tip = jaw[np.argmax(obj.rest_vertices[jaw, 0])]
    skull_tip = skull[np.argmax(obj.rest_vertices[skull, 0])]
    assert moved[jaw_tip] > 0.02 and moved[skull_tip] > 0.02
    # the mouth opened: the lip tips are farther apart than at rest
    gap_now = np.linalg.norm(now[jaw_tip] - now[skull_tip])
    gap_rest = np.linalg.norm(obj.rest_vertices[jaw_tip] - obj.rest_vertices[skull_tip])
    assert gap_now > gap_rest + 0.02


@pytest.mark.slow
def test_shipped_motion_drives_the_creature():
    obj = MedialObject.shipped("medial_caterpillar", constraint="spring_reduction")
    import characters
    folder = os.path.join(os.path.dirname(characters.__file__), "assets")
    motion = Motion.load(os.path.join(folder, "medial_caterpillar.motion.json"))
    fps = 25
    jaw = obj.joints.vertices_of("jaw")
    openings = []
    for frame in range(int(motion.duration * fps)):
        targets = motion.sample(frame / fps)
        obj.step(1.0 / fps, targets)
        openings.append(np.mean(obj.surface()[jaw, 1]))
    assert np.all(np.isfinite(obj.state.x))
    assert np.ptp(openings) > 0.01     # the jaw chattered [m]


def test_reset_and_absent_targets(bunny_mesh):
    obj = MedialObject.from_mesh(bunny_mesh, material="water", joints=[BUNNY_CUT],
                                 check_self_intersections=False)
    rest = obj.surface()
    assert rest.shape == (obj.vertex_count, 3)
    faces = obj.faces.copy()
    for _ in range(10):
        obj.step(0.04, {"top": 0.4})
    assert np.linalg.norm(obj.surface() - rest, axis=1).max() > 0.1
    np.testing.assert_array_equal(obj.faces, faces)
    # the surface is a copy: changing it does not change the object
    obj.surface()[:] = 0.0
    assert np.abs(obj.state.x[:obj.vertex_count]).max() > 0
    obj.reset()
    np.testing.assert_array_equal(obj.surface(), rest)
    assert not obj.state.v.any()
    # an absent target relaxes to angle 0: the bones go back to rest
    for _ in range(5):
        obj.step(0.04, {"top": 0.4})
    obj.step(0.04, None)
    count = obj.vertex_count
    np.testing.assert_allclose(obj.state.x[count:], obj.model.rest_positions[count:], atol=1e-12)


def test_substeps_keep_verlet_below_its_stability_limit(bunny_mesh):
    obj = MedialObject.from_mesh(bunny_mesh, material="skin", check_self_intersections=False)
    for dt in (1 / 60, 1 / 25, 0.1):
        substeps = obj.substeps_for(dt)
        assert dt / substeps <= obj.max_substep
        assert dt / (substeps - 1 or 1) > obj.max_substep or substeps == 1
    # a 1/25 s frame in one explicit step would blow up without constraints: the limit is real
    k_over_m = obj.material.stiffness
    assert obj.max_substep < 2.0 / np.sqrt(k_over_m)


@pytest.mark.slow
def test_bone_spring_reduction_matches_the_core_constraint(bunny_mesh, rng):
    """The medial kernel (per point, early stop) against the core's SpringReductionConstraint
    (every pass over every spring) on the same violent positions: the same result."""
    from characters import SpringReductionConstraint

    obj = MedialObject.from_mesh(bunny_mesh, material="water", constraint="spring_reduction",
                                 joints=[BUNNY_CUT], check_self_intersections=False)
    ours = obj.model.constraints[0]
    core = SpringReductionConstraint(obj.bone_spring_index, min_factor=ours.min_factor,
                                     max_factor=ours.max_factor, iterations=ours.iterations)
    core.check(obj.model)
    dyn = obj.dynamic_vertices
    for scale in (0.01, 0.1, 1.0):
        x = obj.model.rest_positions.copy()
        x[dyn] += rng.normal(scale=scale, size=(len(dyn), 3))
        v = rng.normal(size=x.shape)
        x_core, v_core = x.copy(), v.copy()
        left_ours = ours.apply(x, v, 0.01, obj.model.inverse_mass)
        left_core = core.apply(x_core, v_core, 0.01, obj.model.inverse_mass)
        np.testing.assert_allclose(x, x_core, rtol=0, atol=1e-12)
        np.testing.assert_allclose(v, v_core, rtol=0, atol=1e-9)
        assert left_ours == pytest.approx(left_core, abs=1e-12)
        assert core.violation(x) < 1e-6


def test_the_compiled_frame_steps_as_the_substep_loop(bunny_mesh):
    """One compiled call per frame (circumsphere) against the integrator's Python substep loop
    with the bones posed per substep, on the same targets: the same states, bit for bit."""
    compiled, looped = (MedialObject.from_mesh(bunny_mesh, material="water", joints=[BUNNY_CUT],
                                               check_self_intersections=False) for _ in range(2))
    assert compiled.integrator._frame is not None
    looped.integrator._frame = None          # the base class's loop with the posing hook
    for k in range(12):
        targets = {"top": 0.5 * np.sin(0.7 * k)} if k < 9 else {}
        compiled.step(0.04, targets)
        looped.step(0.04, targets)
        np.testing.assert_array_equal(compiled.state.x, looped.state.x)
        np.testing.assert_array_equal(compiled.state.v, looped.state.v)
    assert np.abs(compiled.surface() - compiled.rest_vertices).max() > 1e-3
