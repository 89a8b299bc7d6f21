"""Real faults for the fault-injection tests: a small file system that fills up, run in a
private mount namespace so nothing outlives the process under test.

`small_disk_prefix()` says how this machine can mount one: `unshare -m` as root (the usual
case here and in CI), else `unshare -rm` (an unprivileged user namespace); None when neither
works, and the tests that need it skip with the reason. The file system is a tmpfs of a few
hundred KB: its writes fail with a real ENOSPC, exactly as a full disk's do.
"""
from __future__ import annotations

import functools
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@functools.lru_cache(maxsize=1)
def small_disk_prefix() -> tuple[str, ...] | None:
    """The command prefix that gives a child its own mount namespace, or None."""
    if shutil.which("unshare") is None:
        return None
    for prefix in (("unshare", "-m"), ("unshare", "-rm")):
        probe = subprocess.run([*prefix, "sh", "-c",
                                "d=$(mktemp -d) && mount -t tmpfs -o size=64k tmpfs \"$d\""],
                               capture_output=True)
        if probe.returncode == 0:
            return prefix
    return None


def mop_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.setdefault("PYOPENGL_PLATFORM", "egl")
    return env


def run_on_small_disk(argv: list[str], *, disk: Path, size_kb: int, keep: Path | None = None,
                      fill_when_exists: str | None = None,
                      cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `python -m mop ARGV` with a fresh tmpfs of `size_kb` KB mounted on `disk` (visible to
    that process only). `fill_when_exists`: a path under `disk`; once it exists (and has grown
    for a moment) the rest of the disk is filled with zeros while mop runs, so the fault comes
    mid-work. Afterwards the disk's files are copied to `keep` (the tmpfs vanishes with the
    namespace)."""
    prefix = small_disk_prefix()
    if prefix is None:
        raise RuntimeError("no private mount namespace available")
    disk.mkdir(parents=True, exist_ok=True)
    mop = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "mop", *argv])
    quoted = shlex.quote(str(disk))
    lines = [f"mount -t tmpfs -o size={int(size_kb)}k tmpfs {quoted} || exit 97"]
    if fill_when_exists:
        target = shlex.quote(fill_when_exists)
        lines += [f"{mop} & pid=$!",
                  f"for i in $(seq 1 600); do [ -s {target} ] && break; sleep 0.05; done",
                  "sleep 0.5",
                  f"dd if=/dev/zero of={quoted}/filler bs=4k 2>/dev/null; sync",
                  "wait $pid; rc=$?",
                  f"rm -f {quoted}/filler"]
    else:
        lines += [f"{mop}; rc=$?"]
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        lines += [f"cp -a {quoted}/. {shlex.quote(str(keep))}/ 2>/dev/null"]
    lines += ["exit $rc"]
    return subprocess.run([*prefix, "sh", "-c", "\n".join(lines)], capture_output=True,
                          text=True, cwd=cwd or ROOT, env=mop_env(), timeout=timeout)
