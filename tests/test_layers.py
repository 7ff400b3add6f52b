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
    for path in sorted((ROOT / "mjx_pick" / "gui").rglob("*.py")):
        yield "gui", path  # the GUI package (and its page/): the interface layer, like the CLI


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


# Inside the GUI, the same rule: the framework-free modules, then the page's shared parts,
# then the tabs (which never import each other), then the server that wires them.
GUI = ROOT / "mjx_pick" / "gui"
GUI_LEVELS = {
    "no web framework": (
        "__init__",
        "forms",
        "jobs",
        "views",
        "uploads",
        "formatting",
        "state",
        "one_pick",
    ),
    "page parts": ("page", "page.widgets", "page.settings_form", "page.job_panel"),
    "tabs": (
        "page.import_tab",
        "page.gripper_tab",
        "page.generate_tab",
        "page.analyze_tab",
        "page.sweep_tab",
        "page.studies_tab",
    ),
    "server": ("app",),
}
GUI_ORDER = list(GUI_LEVELS)
# the package's serve() starts the server on demand: its one look upward, inside serve()
GUI_ALLOWED_UP = {("__init__", "app")}


def gui_name(path: Path) -> str:
    """``page/job_panel.py`` -> ``page.job_panel``; a package's ``__init__`` -> its name."""
    parts = list(path.relative_to(GUI).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts.pop()
    return ".".join(parts)


def gui_level(name: str) -> str:
    for level, names in GUI_LEVELS.items():
        if name in names:
            return level
    raise KeyError(name)


def gui_imports(path: Path) -> set[str]:
    """Every mjx_pick.gui module a file imports (``page.job_panel``, ``forms``, ...)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module.startswith("mjx_pick.gui."):
                names = [node.module.removeprefix("mjx_pick.gui.")]
            elif node.module == "mjx_pick.gui":  # from mjx_pick.gui import forms, jobs
                names = [a.name for a in node.names]
            elif node.module == "mjx_pick.gui.page":
                names = [f"page.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [
                a.name.removeprefix("mjx_pick.gui.")
                for a in node.names
                if a.name.startswith("mjx_pick.gui.")
            ]
        out.update(names)
    return {n for n in out if n in {gui_name(p) for p in GUI.rglob("*.py")}}


def imports_nicegui(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "nicegui":
            return True
        if isinstance(node, ast.Import) and any(
            a.name.split(".")[0] == "nicegui" for a in node.names
        ):
            return True
    return False


def test_every_gui_module_has_a_level():
    unknown = [
        gui_name(p)
        for p in GUI.rglob("*.py")
        if not any(gui_name(p) in v for v in GUI_LEVELS.values())
    ]
    assert not unknown, f"add these GUI modules to GUI_LEVELS in tests/test_layers.py: {unknown}"


@pytest.mark.parametrize("path", sorted(GUI.rglob("*.py")), ids=gui_name)
def test_gui_modules_import_only_down(path):
    name = gui_name(path)
    mine = GUI_ORDER.index(gui_level(name))
    bad = sorted(
        m
        for m in gui_imports(path)
        if (name, m) not in GUI_ALLOWED_UP
        and (
            GUI_ORDER.index(gui_level(m)) > mine
            or (gui_level(m) == "tabs" == gui_level(name) and m != name)  # tab to tab
        )
    )
    assert not bad, f"{path.relative_to(ROOT)} ({gui_level(name)}) imports {bad}"


def test_only_the_page_and_the_server_import_the_web_framework():
    free = [gui_name(p) for p in GUI.rglob("*.py") if gui_level(gui_name(p)) == "no web framework"]
    assert free and not [n for n in free if imports_nicegui(GUI / f"{n.replace('.', '/')}.py")]
