"""Material presets: the papers' numbers survive the TOML round trip; overlays; clear errors."""
import math

import numpy as np
import pytest

from characters import Material, load_materials, material, material_names


def test_medial_table_matches_the_paper():
    # Pfaff & Wuethrich 2007, Table 1: C_vd, D, d_B, sl_max
    table = {"thick_skin": (0.7, 1.0, 0.5, 1.3), "water": (0.99, 1.0, 1.0, 1.4),
             "skin": (0.85, 1.0, 0.2, 1.25), "tight_cloth": (0.85, 0.2, 0.4, 1.35)}
    for name, (cvd, spring_constant, bone, slmax) in table.items():
        m = material(name)
        assert m.family == "medial"
        assert (m.velocity_damping, m.stiffness / 1000.0, m.bone_distance, m.max_stretch) == (
            cvd, spring_constant, bone, slmax)
    plastic = material("plastic")
    assert plastic.bone_distance == 0.0 and plastic.max_stretch == 1.0
    assert plastic.velocity_damping is None and plastic.stiffness is None  # "var"


def test_families_and_names():
    assert set(material_names("medial")) == {"thick_skin", "water", "plastic", "skin",
                                             "tight_cloth"}
    assert set(material_names("animatron")) == {"liquid", "fabric", "rubber", "rigid"}
    assert {"latex_skin", "latex_foam", "latex_cavity"} <= set(material_names("latex"))
    with pytest.raises(ValueError, match="family must be one of"):
        material_names("wood")
    with pytest.raises(ValueError, match="unknown material 'wood'"):
        material("wood")


def test_animatron_ordering():
    # the article: liquid low/low < fabric medium/medium < rigid high/high;
    # rubber stiff, soft damping
    liquid, fabric, rubber, rigid = (material(n) for n in ("liquid", "fabric", "rubber", "rigid"))
    assert liquid.stiffness < fabric.stiffness < rubber.stiffness < rigid.stiffness
    assert liquid.damping < fabric.damping < rigid.damping
    assert rubber.damping < fabric.damping


def test_latex_layers_skin_stiffer_than_foam():
    skin, foam = material("latex_skin"), material("latex_foam")
    assert skin.youngs_modulus > 10 * foam.youngs_modulus
    k, c, m = skin.lattice_parameters(np.array([0.004, 0.005]), spacing=0.004)
    np.testing.assert_allclose(k, skin.youngs_modulus * np.array([0.004, 0.005]))
    assert m == pytest.approx(skin.density * 0.004 ** 3)
    assert np.all(c > 0)
    with pytest.raises(ValueError, match="no youngs_modulus"):
        material("skin").lattice_parameters([0.01], spacing=0.01)
    with pytest.raises(ValueError, match="no per-mass stiffness"):
        skin.spring_parameters(1.0)


def test_frozen_and_rates():
    skin = material("skin")
    with pytest.raises(AttributeError):
        skin.stiffness = 3.0
    # C_vd is the velocity kept per 1/25 s: after 1/25 s at the rate, exactly C_vd remains
    assert math.exp(-skin.velocity_damping_rate() / 25.0) == pytest.approx(0.85)
    k, c = material("fabric").spring_parameters(0.5)
    assert k == pytest.approx(200.0) and c == pytest.approx(2.0)
    assert isinstance(skin, Material)


def test_overlay(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('[skin]\nvelocity_damping = 0.5\n\n[jelly]\nfamily = "medial"\n'
                    'stiffness = 300.0\nvelocity_damping = 0.97\n')
    table = load_materials(path)
    assert table["skin"].velocity_damping == 0.5 and table["skin"].bone_distance == 0.2
    assert table["jelly"].stiffness == 300.0
    assert material("skin").velocity_damping == 0.85  # built-in untouched
    with pytest.raises(TypeError):
        table["x"] = 1


@pytest.mark.parametrize("text, message", [
    ('[skin]\ncolour = 3\n', r"mine.toml: \[skin\] has unknown key\(s\) \['colour'\]"),
    ('[skin]\nstiffness = "hard"\n', r"\[skin\] stiffness must be a number"),
    ('[skin]\nstiffness = -1.0\n', r"\[skin\] stiffness must be finite and >= 0"),
    ('[skin]\nvelocity_damping = 1.5\n', r"velocity_damping .* must be in \(0, 1\]"),
    ('[goo]\nstiffness = 1.0\n', r"\[goo\] family must be one of"),
    ('[skin\n', "not valid TOML"),
])
def test_overlay_errors_name_file_and_key(tmp_path, text, message):
    path = tmp_path / "mine.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_materials(path)
