"""Layers only look down (DESIGN.md): core -> engine -> studies -> outputs -> interfaces.

Every ``mjx_pick`` import in every module -- at the top or inside a function -- is read
from the source with ``ast``; a module may import its own layer or a lower one only.
"""

import ast
from pathlib import Path

import pytest

import mjx_pick

ROOT = Path(__file__).resolve().parents[1]

LAYERS = {
    # core: the data model, the physics set-up and the device kernels
    "core": (
        "config",
        "objects",
        "gripper",
        "mjcf_gripper",
        "physics",
        "grasp",
        "scene",
        "holding",
        "pickpoints",
        "pickfiles",
        "metrics",
        "plots",
        "rundir",
        "display",
        "progress",
        "interrupts",
        "kernels",
        "assets",
    ),
    # engine: backends and the runner every study simulates through
    "engine": ("simulate", "engine", "backend_mjx", "backend_mujoco", "backend_warp", "cluster"),
    "studies": ("evaluation", "sweeps", "comparison", "robust", "calibration", "throughput"),
    "outputs": ("reporting", "trials"),
    "interfaces": ("cli", "__init__", "__main__", "gui"),
}
ORDER = list(LAYERS)


def layer_of(module: str) -> str:
    for layer, names in LAYERS.items():
        if module in names:
            return layer
    raise KeyError(module)


def modules():
    for path in sorted((ROOT / "mjx_pick").glob("*.py")):
        yield path.stem, path
    for path in sorted((ROOT / "mjx_pick" / "kernels").glob("*.py")):
        yield "kernels", path
    for path in sorted((ROOT / "mjx_pick" / "calibration").rglob("*.py")):
        yield "calibration", path  # the calibration package: a study
    for path in sorted((ROOT / "mjx_pick" / "reporting").glob("*.py")):
        yield "reporting", path  # the report package: the outputs layer
    for path in sorted((ROOT / "mjx_pick" / "cli").glob("*.py")):
        yield "cli", path  # the command line: the interface layer
    for path in sorted((ROOT / "mjx_pick" / "gui").glob("*.py")):
        yield "gui", path  # the GUI package: the interface layer, like the CLI


def imported(path: Path) -> set[str]:
    """First component after ``mjx_pick.`` of every import of the package in a file."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            parts = node.module.split(".")
            if parts[0] == "mjx_pick":
                if len(parts) > 1:
                    out.add(parts[1])
                else:  # from mjx_pick import x: a module, or a public name of its module
                    out.update(mjx_pick._PUBLIC.get(a.name, a.name) for a in node.names)
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] == "mjx_pick" and len(parts) > 1:
                    out.add(parts[1])
    return out


def test_every_module_has_a_layer():
    unknown = [name for name, _ in modules() if not any(name in v for v in LAYERS.values())]
    assert not unknown, f"add these modules to a layer in tests/test_layers.py: {unknown}"


@pytest.mark.parametrize("name,path", list(modules()), ids=lambda v: str(v))
def test_imports_only_look_down(name, path):
    mine = ORDER.index(layer_of(name))
    upward = sorted(m for m in imported(path) if ORDER.index(layer_of(m)) > mine)
    assert not upward, f"{path.relative_to(ROOT)} ({layer_of(name)}) imports {upward}"


def test_the_check_sees_function_level_imports(tmp_path):
    # the check itself: an import hidden in a function is still seen
    src = tmp_path / "m.py"
    src.write_text("def f():\n    from mjx_pick.reporting import report\n")
    assert imported(src) == {"reporting"}
    src.write_text("def f():\n    from mjx_pick import sweep\n")  # a public function
    assert imported(src) == {"sweeps"}
