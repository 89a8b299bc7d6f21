"""Every puppet kind, and the session's test stand-in, has the shape `characters.Puppet` names;
the session builds every kind a session file may name through its registry, and every kind
package under `characters/` is one a session file may name."""
from pathlib import Path

import numpy as np
import pytest

from characters import ImagePuppet, LatexPuppet, MedialObject, Puppet
from mop.session.config import CharacterKind
from mop.session.puppets import KINDS, register
from session_standin import StripPuppet

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("cv2")


def _image_puppet():
    picture = np.full((96, 96, 3), 250, np.uint8)
    picture[20:80, 30:66] = (200, 60, 40)
    return ImagePuppet.from_image(picture)


def _latex_puppet():
    pybullet_data = pytest.importorskip("pybullet_data")
    return LatexPuppet.from_mesh(f"{pybullet_data.getDataPath()}/bunny.obj", masses=400)


def _medial_puppet():
    return MedialObject.from_mesh(trimesh.creation.icosphere(subdivisions=2))


@pytest.mark.parametrize("make", [_image_puppet, _latex_puppet, _medial_puppet, StripPuppet],
                         ids=["image", "latex", "medial", "standin"])
def test_every_kind_is_a_puppet_and_steps_through_the_protocol(make):
    puppet = make()
    assert isinstance(puppet, Puppet)
    rest = np.array(puppet.surface())
    faces = np.asarray(puppet.faces)
    assert faces.ndim == 2 and faces.shape[1] == 3 and faces.max() < len(rest)
    assert isinstance(puppet.target_names, tuple)
    puppet.step(0.04, {})                       # no targets: stays at rest
    np.testing.assert_allclose(puppet.surface(), rest, atol=1e-6 * np.ptp(rest))
    puppet.reset()
    np.testing.assert_array_equal(puppet.state.x, puppet.model.state().x)


def test_something_without_step_is_not_a_puppet():
    class Statue:
        model = state = faces = target_names = None

        def reset(self):
            pass

        def surface(self):
            return np.zeros((3, 3))

    assert not isinstance(Statue(), Puppet)


def test_every_kind_package_is_one_a_session_may_name():
    import characters
    packages = {path.parent.name for path in Path(characters.__file__).parent.glob("*/puppet.py")}
    assert packages == {kind.value for kind in CharacterKind}, (
        "a package under characters/ with a puppet.py is a puppet kind: name it in "
        "mop.session.config.CharacterKind and register its builder in mop.session.puppets")


def test_every_kind_a_session_may_name_has_one_builder():
    assert set(KINDS) == set(CharacterKind)
    with pytest.raises(ValueError, match="registered already"):
        register(CharacterKind.IMAGE)(lambda character, height: None)
