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
