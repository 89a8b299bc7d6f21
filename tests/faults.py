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
                      fill_when_exists: str | None = None, prefill: bool = False,
                      snapshot: Path | None = None, setup: str = "",
                      cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `python -m mop ARGV` with a fresh tmpfs of `size_kb` KB mounted on `disk` (visible to
    that process only). `setup`: shell lines run once the disk is mounted. `prefill`: the disk
    is full before mop starts. `fill_when_exists`: a path under `disk`; once it exists and mop
    has printed "GO" (and a second later) the disk's files are copied to `snapshot` (what was
    there just before the fault) and the rest of the disk is filled with zeros while mop runs,
    so the fault comes mid-work. Afterwards the filler is removed and the disk's files are
    copied to `keep` (the tmpfs vanishes with the namespace)."""
    prefix = small_disk_prefix()
    if prefix is None:
        raise RuntimeError("no private mount namespace available")
    disk.mkdir(parents=True, exist_ok=True)
    mop = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "mop", *argv])
    quoted = shlex.quote(str(disk))
    fill = f"dd if=/dev/zero of={quoted}/filler bs=4k 2>/dev/null; sync"
    lines = [f"mount -t tmpfs -o size={int(size_kb)}k tmpfs {quoted} || exit 97", setup]
    if prefill:
        lines += [fill]
    if fill_when_exists:
        # mop's output goes through a file so that the fill can wait for its word that the
        # work is under way ("GO" for a recording), then a moment more
        target = shlex.quote(fill_when_exists)
        log = shlex.quote(str(disk.parent / "mop-output.txt"))
        lines += [f"{mop} > {log} & pid=$!",
                  f"for i in $(seq 1 1200); do [ -s {target} ] && grep -q 'GO' {log} && break;"
                  f" sleep 0.05; done",
                  "sleep 1"]
        if snapshot is not None:
            snapshot.mkdir(parents=True, exist_ok=True)
            lines += [f"cp -a {quoted}/. {shlex.quote(str(snapshot))}/"]
        lines += [fill, "wait $pid; rc=$?", f"cat {log}"]
    else:
        lines += [f"{mop}; rc=$?"]
    lines += [f"rm -f {quoted}/filler"]
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        lines += [f"cp -a {quoted}/. {shlex.quote(str(keep))}/ 2>/dev/null"]
    lines += ["exit $rc"]
    return subprocess.run([*prefix, "sh", "-c", "\n".join(lines)], capture_output=True,
                          text=True, cwd=cwd or ROOT, env=mop_env(), timeout=timeout)
