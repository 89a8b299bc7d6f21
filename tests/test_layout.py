"""The layout's rules, read from the code's own imports (every `import` statement, at module
level or inside a function, parsed with `ast`):

- `capture`, `followers` and `characters` never import each other, nor `mop`;
- every module has a place in LAYERS below (kernels and data types low, builders and the CLI
  high; a package's `__init__` is its facade and has none), and a low module never imports a
  higher one: a new module is added to LAYERS at its level, or this test names it;
- the puppet kinds (every package under `characters/` with a `puppet` module) never import
  each other; inside a kind, only its runtime `puppet` composes the builders (nothing else in
  the kind imports it);
- a plain `import capture / followers / characters` loads none of the heavy libraries.
"""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("capture", "followers", "characters", "mop")
LIBRARIES = ("capture", "followers", "characters")
#: the puppet kinds: every package under characters/ that has a runtime `puppet.py`
KINDS = tuple(sorted(f"characters.{path.parent.name}"
                     for path in (ROOT / "characters").glob("*/puppet.py")))

# Lowest first. A module (or a package prefix ending in ".*") of one layer may import modules
# of its own layer and of the layers before it, never of the layers after it.
LAYERS = {
    "capture": [
        ["capture.frame", "capture.clock", "capture.resample", "capture.store",
         "capture.profiles", "capture.hid.parse", "capture.hid.profile", "capture.hid.status",
         "capture.hid.calibration", "capture.camera.base", "capture.camera.landmarks",
         "capture.camera.smoothing", "capture.camera.markerless", "capture.camera.trackers"],
        ["capture.source"],
        ["capture.osc", "capture.replay", "capture.hid.source", "capture.camera.source"],
        ["capture.spec", "capture.devices"],
    ],
    "followers": [
        ["followers._jit", "followers._exp", "followers._cells", "followers._kernels",
         "followers._bank_kernels",
         "followers._baum_welch", "followers.bank_output",
         "followers.config", "followers.defaults", "followers.preprocessing",
         "followers.transitions", "followers.datasets", "followers.model",
         "followers.still", "followers.intervals", "followers.calibration",
         "followers.novelty"],
        ["followers.bank_model"],
        ["followers.follower", "followers.demos"],
        ["followers.bank", "followers.training"],
        ["followers.confusion"],
    ],
    "characters": [
        ["characters.kernels", "characters.sidecar"],
        ["characters.model", "characters.control", "characters.motion", "characters.materials",
         "characters.constraints"],
        ["characters.integrators", "characters.puppet"],
        [f"{kind}.*" for kind in KINDS],
        ["characters.assets.*"],
    ],
    "mop": [
        ["mop.export", "mop.render.compose", "mop.sidecars", "mop.takes", "mop.session.config",
         "mop.session.timing", "mop.session.feeds"],
        ["mop.render.image2d", "mop.render.scene3d", "mop.session.loop", "mop.session.outputs",
         "mop.session.preview", "mop.session.puppets", "mop.session.worker"],
        ["mop.session.build"],
        ["mop.commands.*", "mop.cli", "mop.__main__"],
    ],
}

HEAVY = ("cv2", "pyrender", "moderngl", "trimesh", "hid", "hidraw", "matplotlib", "hmmlearn",
         "mediapipe", "OpenGL")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found[_module_name(path)] = path
    return found


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The module of ours that `name` (a module or a module.attribute) lands in, if any."""
    while name:
        if name in MODULES:
            return name
        name = name.rpartition(".")[0]
    return None


def _imports(module: str) -> dict[str, int]:
    """{module of ours imported: line} for every import statement of `module`."""
    path = MODULES[module]
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found = {}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module
            # `from pkg import sub` imports the submodule; `from mod import name` the module
            targets = [f"{source}.{alias.name}" if f"{source}.{alias.name}" in MODULES
                       else source for alias in node.names]
        else:
            continue
        for target in targets:
            resolved = _resolve(target)
            if resolved is not None and resolved != module:
                found.setdefault(resolved, node.lineno)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, int]]:
    """{module: {module of ours it imports: line}} for every module (parsed when first asked)."""
    return {module: _imports(module) for module in MODULES}


def _layer(module: str) -> int | None:
    for index, layer in enumerate(LAYERS[module.split(".")[0]]):
        for entry in layer:
            if module == entry or (entry.endswith(".*") and (
                    module == entry[:-2] or module.startswith(entry[:-1]))):
                return index
    return None


def _where(module: str, line: int) -> str:
    return f"{MODULES[module].relative_to(ROOT)}:{line}"


def test_the_libraries_never_import_each_other_nor_mop(graph):
    wrong = [f"{_where(m, line)} {m} imports {target}"
             for m, imported in graph.items() if m.split(".")[0] in LIBRARIES
             for target, line in imported.items()
             if target.split(".")[0] != m.split(".")[0]]
    assert not wrong, "\n".join(wrong)


def test_low_modules_never_import_high_ones(graph):
    wrong = []
    for module, imported in graph.items():
        low = _layer(module)
        if low is None:
            continue
        for target, line in imported.items():
            if target.split(".")[0] != module.split(".")[0]:
                continue
            high = _layer(target)
            if high is not None and high > low:
                wrong.append(f"{_where(module, line)} {module} (layer {low}) imports {target} "
                             f"(layer {high})")
    assert not wrong, "\n".join(wrong)


def test_the_layers_name_modules_that_exist():
    for layers in LAYERS.values():
        for layer in layers:
            for entry in layer:
                name = entry[:-2] if entry.endswith(".*") else entry
                assert name in MODULES, f"LAYERS names {entry}, which is not a module"


def test_every_module_has_a_layer():
    facades = {name for name, path in MODULES.items() if path.name == "__init__.py"}
    missing = sorted(name for name in MODULES if name not in facades and _layer(name) is None)
    assert not missing, (
        "modules without a layer; add each to LAYERS[package] in tests/test_layout.py at its "
        "level (low: kernels, data types, configuration; high: builders, commands): "
        + ", ".join(missing))


def test_the_three_kinds_are_found():
    assert KINDS == ("characters.image", "characters.latex", "characters.medial")


def test_puppet_kinds_are_siblings_and_their_runtime_is_on_top(graph):
    wrong = []
    for module, imported in graph.items():
        kind = next((k for k in KINDS if module == k or module.startswith(k + ".")), None)
        if kind is None:
            continue
        for target, line in imported.items():
            other = next((k for k in KINDS if target == k or target.startswith(k + ".")), None)
            if other is not None and other != kind:
                wrong.append(f"{_where(module, line)} {module} imports another kind: {target}")
            if target == f"{kind}.puppet" and module != kind:
                wrong.append(f"{_where(module, line)} {module} imports its kind's runtime")
    assert not wrong, "\n".join(wrong)


def test_the_checker_sees_relative_and_function_level_imports(graph):
    # characters.latex.puppet: `from . import connection` at the top, and
    # characters.assets.caterpillar: `from ..motion import Motion` inside a function
    assert "characters.latex.connection" in graph["characters.latex.puppet"]
    assert "characters.motion" in graph["characters.assets.caterpillar"]


@pytest.mark.parametrize("package", LIBRARIES)
def test_a_plain_import_loads_no_heavy_library(package):
    code = (f"import sys, {package}; "
            f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [], f"import {package} loaded {result.stdout.strip()}"
