"""The `mop` command's errors: every failure is one line naming the problem (the traceback only
with --debug), and ports, durations and rates are checked before any work starts."""
import subprocess
import sys

import pytest

from mop.cli import describe_error, main


@pytest.mark.parametrize("argv, message", [
    (["perform", "sessions/demo.toml", "--preview", "99999"], "port is an integer 0..65535"),
    (["perform", "sessions/demo.toml", "--preview", "-1"], "port is an integer 0..65535"),
    (["perform", "sessions/demo.toml", "--duration", "-1"], "a duration is > 0"),
    (["perform", "sessions/demo.toml", "--duration", "nan"], "finite number"),
    (["demo", "--preview", "70000"], "port is an integer 0..65535"),
    (["demo", "--still-at", "-5"], "a time is >= 0"),
    (["puppet", "x.png", "--duration", "inf"], "finite number"),
    (["puppet", "x.png", "--fps", "0"], "a rate is > 0"),
    (["plot", "take", "--fps", "0"], "a rate is > 0"),
    (["plot", "take", "--fps", "100000"], "at most 1000 Hz"),
    (["plot", "take", "--fps", "2.5"], "whole number"),
    (["send", "replay:x", "--to", "127.0.0.1:9", "--duration", "nan"], "finite number"),
    (["record", "--performer", "a", "--action", "b", "--motion", "m", "--source", "s",
      "--countdown", "-3"], "a time is >= 0"),
])
def test_bad_numbers_are_refused_before_any_work(argv, message, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err



def test_every_exception_type_becomes_one_line(monkeypatch, capsys):
    import mop.commands.devices as devices

    for error, expected in [
            (RuntimeError("the\nthing broke"), "RuntimeError: the thing broke"),
            (ModuleNotFoundError("No module named 'x'"), "ModuleNotFoundError"),
            (OSError(28, "No space left on device", "out.mp4"), "out.mp4: No space left"),
            (KeyError("no take 'x'"), "no take 'x'"),
            (MemoryError(), "out of memory")]:
        def broken(args, error=error):
            raise error
        monkeypatch.setattr(devices, "run", broken)
        code = main(["devices"])
        err = capsys.readouterr().err
        assert code == 1, error
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("mop devices: error: "), err
        assert expected in lines[0], (expected, err)


def test_debug_shows_the_traceback():
    code = ("import sys, mop.commands.devices as d, mop.cli as c\n"
            "def broken(args):\n"
            "    return 1 / 0\n"
            "d.run = broken\n"
            "sys.exit(c.main(sys.argv[1:]))\n")
    quiet = subprocess.run([sys.executable, "-c", code, "devices"], capture_output=True,
                           text=True)
    assert quiet.returncode == 1
    assert "ZeroDivisionError: division by zero" in quiet.stderr
    assert "--debug" in quiet.stderr and "Traceback" not in quiet.stderr
    loud = subprocess.run([sys.executable, "-c", code, "--debug", "devices"],
                          capture_output=True, text=True)
    assert loud.returncode != 0 and "Traceback" in loud.stderr


def test_describe_error_joins_lines_and_bounds_length():
    assert describe_error(ValueError("a\n  b")) == "a b"
    assert len(describe_error(ValueError("x" * 10000))) == 2000
