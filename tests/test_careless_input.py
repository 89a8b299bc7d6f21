"""What a careless user does through the CLI and the files: each gets a clear error or the
sensible result, never an exit 0 with nothing done."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mop.cli import main
from mop.export import NullWriter, open_writer

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "characters" / "assets"
TAKES = ROOT / "recordings" / "demo"


def _frames(count=3, size=(8, 6)):
    width, height = size
    return [np.full((height, width, 4), 40 * k, np.uint8) for k in range(count)]


def test_png_frames_never_mix_with_an_earlier_render(tmp_path):
    folder = tmp_path / "frames"
    with open_writer(folder, fps=25, size=(8, 6)) as writer:
        for frame in _frames(3):
            writer.write(frame)
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="already holds 3 frame"):
        open_writer(folder, fps=25, size=(8, 6))
    with open_writer(folder, fps=25, size=(8, 6), overwrite=True) as writer:
        writer.write(_frames(1)[0])
    assert sorted(p.name for p in folder.iterdir()) == ["frame_000000.png", "notes.txt"]


def test_dev_null_drops_the_frames(capsys):
    with open_writer("/dev/null", fps=25, size=(8, 6)) as writer:
        assert isinstance(writer, NullWriter)
        for frame in _frames(4):
            writer.write(frame)
    assert writer.frames_written == 4
    assert main(["puppet", str(DATA / "momo.png"), "--motion", str(DATA / "momo_wave.json"),
                 "--out", "/dev/null", "--duration", "0.2"]) == 0
    assert "wrote /dev/null: 6 frames" in capsys.readouterr().out


@pytest.mark.slow
def test_a_record_preview_stays_in_its_folder_whatever_the_action_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "deep" / "er").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "deep" / "er")
    code = main(["record", "--performer", "ann", "--action", "../../../x", "--motion",
                 str(DATA / "momo_wave.json"), "--source", "replay:" + str(TAKES / "glove_show"),
                 "--recordings", "takes", "--countdown", "0"])
    assert code == 0
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*.*"))
    assert [p.parent for p in written] == [Path("deep/er/out"), Path("deep/er/takes")]
    assert written[0].name == "preview-x.mp4"


def test_replay_loop_without_an_end_is_refused(tmp_path, capsys):
    from session_files import write_session
    session = write_session(tmp_path)
    assert main(["perform", str(session), "--replay", "--loop", "--out",
                 str(tmp_path / "x.mp4")]) == 1
    assert "--loop replays the takes forever" in capsys.readouterr().err
    assert not (tmp_path / "x.mp4").exists()


def test_send_that_sends_nothing_is_an_error(tmp_path, capsys):
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a picture")
    code = main(["send", f"camera:{junk}:aruco", "--to", "127.0.0.1:9", "--duration", "0.5",
                 "--quiet"])
    assert code == 1
    assert "gave no frame" in capsys.readouterr().err


def test_takes_export_never_overwrites_without_force_and_writes_into_a_folder(tmp_path,
                                                                              capsys):
    import shutil
    folder = tmp_path / "takes"
    folder.mkdir()
    shutil.copy(TAKES / "glove_chomp.sqlite", folder / "chomp.sqlite")
    out = tmp_path / "exports"
    out.mkdir()
    base = ["takes", "--recordings", str(folder), "export", "chomp"]
    assert main([*base, "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["chomp.npz"]
    assert main([*base, "--out", str(out)]) == 1
    assert "already exist" in capsys.readouterr().err
    assert main([*base, "--out", str(out), "--force"]) == 0
    assert main([*base, "--out", str(out / "csv") + "/", "--format", "csv"]) == 0
    assert sorted(p.name for p in (out / "csv").iterdir()) == ["chomp.aligned.csv", "chomp.csv"]


@pytest.mark.parametrize("change, message", [
    ({"fixed": "false"}, "must be true or false, got 'false' (a string)"),
    ({"fixed": 0}, "must be true or false"),
    ({"xy": [1, "2"]}, "must be a number"),
    ({"xy": [1, True]}, "must be a number"),
    ({"xy": [1, 2, 3]}, "list of 2 numbers"),
    ({"xy": [1, float("nan")]}, "must be finite"),
    ({"fixd": True}, "unknown key(s) 'fixd'"),
])
def test_pins_files_are_read_strictly(change, message, tmp_path):
    import json

    from mop.sidecars import read_pins
    document = json.loads((DATA / "momo.pins.json").read_text())
    document["pins"]["head"].update(change)
    path = tmp_path / "momo.pins.json"
    path.write_text(json.dumps(document))
    with pytest.raises((TypeError, ValueError), match=None) as raised:
        read_pins(path)
    assert message in str(raised.value) and str(path) in str(raised.value)


@pytest.mark.parametrize("version", [99, 0, "1", True, 1.0])
def test_sidecar_versions_this_mop_does_not_read_are_refused(version, tmp_path):
    import json

    from characters import Motion
    from mop.sidecars import read_pins
    for name, reader in (("momo.pins.json", read_pins), ("momo_wave.json", Motion.load)):
        document = json.loads((DATA / name).read_text())
        document["version"] = version
        path = tmp_path / name
        path.write_text(json.dumps(document))
        with pytest.raises((TypeError, ValueError), match="version"):
            reader(path)


def _long_motion(tmp_path, seconds=4e6) -> Path:
    import json
    document = json.loads((DATA / "momo_wave.json").read_text())
    for channel in document["channels"].values():
        last = channel["times"][-1]
        channel["times"] = [t * seconds / last for t in channel["times"]]
    path = tmp_path / "long.json"
    path.write_text(json.dumps(document))
    return path


def test_a_render_of_a_huge_motion_is_refused_with_the_limit(tmp_path, capsys):
    motion = _long_motion(tmp_path)
    code = main(["puppet", str(DATA / "momo.png"), "--motion", str(motion), "--out",
                 str(tmp_path / "x.mp4")])
    err = capsys.readouterr().err
    assert code == 1
    assert "100,000,001 frames" in err and "--max-frames 100000001" in err
    assert not (tmp_path / "x.mp4").exists()


def test_recording_along_a_huge_motion_is_refused_with_the_limit(tmp_path, capsys):
    code = main(["record", "--performer", "a", "--action", "b", "--motion",
                 str(_long_motion(tmp_path)), "--source", "replay:x", "--recordings",
                 str(tmp_path / "takes"), "--preview", str(tmp_path / "p.mp4")])
    err = capsys.readouterr().err
    assert code == 1
    assert "the motion lasts 4e+06 s" in err and "--max-duration 4000000" in err
    assert not (tmp_path / "p.mp4").exists()


def test_a_work_estimate_warns_once_when_minutes_are_ahead():
    import io

    from mop.commands._args import WorkEstimate
    stream = io.StringIO()
    estimate = WorkEstimate(100_000, "rendering x.mp4", stream=stream, after=0.0)
    estimate.started -= 10.0            # 10 s for the first 10 frames: hours ahead
    assert estimate.update(10) > 3600
    assert estimate.update(20) is None  # said once
    assert stream.getvalue().count("warning: rendering x.mp4: about") == 1


@pytest.mark.parametrize("shape", ["sphere", "two spheres"])
def test_automatic_finger_regions_stay_disjoint_on_ordinary_meshes(shape):
    import trimesh

    from characters import LatexPuppet
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    mesh = sphere if shape == "sphere" else trimesh.util.concatenate(
        [sphere, sphere.copy().apply_translation([0.15, 0, 0])])
    puppet = LatexPuppet.from_mesh(mesh, masses=300)
    regions = list(puppet.regions.values())
    assert len(regions) == 5 and all(len(r) for r in regions)
    members = np.concatenate([np.asarray(r).ravel() for r in regions])
    assert len(np.unique(members)) == len(members)


def test_a_medial_asset_of_random_bytes_or_nan_is_named_for_what_it_is(tmp_path, rng):
    import trimesh

    from characters import MedialObject
    junk = tmp_path / "junk.obj"
    junk.write_bytes(rng.bytes(4096))
    with pytest.raises(ValueError, match="junk.obj"):
        MedialObject.from_mesh(junk)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    vertices = sphere.vertices.copy()
    vertices[7] = np.nan
    nan = tmp_path / "nan.obj"
    trimesh.Trimesh(vertices, sphere.faces, process=False).export(nan)
    with pytest.raises(ValueError, match="1 vertices with NaN or infinite coordinates"):
        MedialObject.from_mesh(nan)


def test_a_medial_mesh_too_large_is_refused_with_how_to_lift_it():
    import trimesh

    from characters import MedialObject
    big = trimesh.creation.icosphere(subdivisions=5)      # 20,480 faces: minutes of Voronoi
    with pytest.raises(ValueError, match="20,480 faces.*max_faces=20480"):
        MedialObject.from_mesh(big)


def test_a_replay_of_a_day_is_refused_with_the_limit(tmp_path, capsys):
    from session_files import write_session
    session = write_session(tmp_path)
    assert main(["perform", str(session), "--replay", "--loop", "--duration", "86400",
                 "--out", str(tmp_path / "x.mp4")]) == 1
    assert "2,160,000 frames" in capsys.readouterr().err
    assert not (tmp_path / "x.mp4").exists()


def test_a_pipe_in_place_of_a_file_is_named_not_waited_on(tmp_path, capsys):
    import os
    folder = tmp_path / "takes"
    folder.mkdir()
    os.mkfifo(folder / "x.sqlite")
    os.mkfifo(tmp_path / "motion.json")
    assert main(["takes", "--recordings", str(folder), "list"]) == 0
    assert "x  DAMAGED: " in capsys.readouterr().out
    assert main(["puppet", str(DATA / "momo.png"), "--motion", str(tmp_path / "motion.json"),
                 "--out", str(tmp_path / "x.mp4")]) == 1
    assert "not a regular file" in capsys.readouterr().err


def test_a_still_past_the_end_of_the_show_is_an_error(tmp_path, capsys):
    from test_faults import SMALL_SESSION
    session = tmp_path / "small.toml"
    session.write_text(SMALL_SESSION)
    code = main(["demo", "--session", str(session), "--quiet", "--out", "/dev/null",
                 "--still", str(tmp_path / "still.png"), "--still-at", "3000"])
    assert code == 1
    assert "--still-at 3000: the session ended at" in capsys.readouterr().err
    assert not (tmp_path / "still.png").exists()


def test_a_run_that_compiles_the_kernels_says_so_first(tmp_path, monkeypatch):
    import io
    import subprocess
    import sys

    from mop.commands._args import kernels_compiled, say_if_kernels_compile

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))       # an empty cache: a fresh install
    said = io.StringIO()
    assert not kernels_compiled() and say_if_kernels_compile(said)
    assert "first run: compiling" in said.getvalue() and "minutes" in said.getvalue()
    # numba itself fills the cache: one small kernel of each package, in a fresh process
    compile_two = ("import numpy as np\n"
                   "from characters.kernels import all_finite\n"
                   "from followers._baum_welch import _log_sum\n"
                   "assert all_finite(np.zeros(3)) and _log_sum(0.0, 0.0) > 0.0\n")
    subprocess.run([sys.executable, "-c", compile_two], check=True)
    said = io.StringIO()
    assert kernels_compiled() and not say_if_kernels_compile(said)
    assert said.getvalue() == ""
