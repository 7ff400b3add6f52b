"""Layers only look down, and no module imports itself round a loop.

The layer of a module is its folder (DESIGN.md, docs/architecture.md), lowest first:
``assets`` and ``kernels``, ``core``, ``outputs``, ``engine``, ``studies``, then the
interfaces (``cli``, ``gui`` and the package's ``__init__``). Every import of the
package in every module -- at the top or inside a function, ``from mjx_pick.x import
y``, ``import mjx_pick.x``, ``from mjx_pick import name`` and ``import mjx_pick as mp``
with its ``mp.name`` uses -- is read from the source with ``ast``; a module may import
its own layer or a lower one only, and the module graph has no cycle.
"""

import ast
from pathlib import Path

import pytest

import mjx_pick

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "mjx_pick"

ORDER = ["data", "core", "outputs", "engine", "studies", "interfaces"]
FOLDER_LAYER = {
    "assets": "data",
    "kernels": "data",  # the device kernels: pure JAX, import nothing of the package
    "core": "core",
    "outputs": "outputs",
    "engine": "engine",
    "studies": "studies",
    "cli": "interfaces",
    "gui": "interfaces",
}


def dotted(path: Path) -> str:
    """mjx_pick/engine/runner.py -> mjx_pick.engine.runner (a package: its name)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str) -> str:
    """The layer of a dotted module name of the package: its first folder's."""
    parts = module.split(".")
    if parts == ["mjx_pick"] or parts[1:] == ["__main__"]:
        return "interfaces"  # the package's face: the lazy public API
    if parts[1] not in FOLDER_LAYER:
        raise KeyError(f"{module}: a module outside the layer folders")
    return FOLDER_LAYER[parts[1]]


def modules() -> dict[str, Path]:
    return {dotted(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def resolve(name: str, known: dict[str, Path]) -> str:
    """The longest known module a dotted name starts with (a name in a module -> it)."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        head = ".".join(parts[:n])
        if head in known:
            return head
    return name


def public(name: str) -> str | None:
    """The module that defines a public name of ``mjx_pick`` (None: not public)."""
    module = mjx_pick._PUBLIC.get(name)
    return f"mjx_pick.{module}" if module else None


def imported(path: Path, known: dict[str, Path] | None = None) -> set[str]:
    """Every module of the package that a file imports, in any form."""
    known = known if known is not None else modules()
    tree = ast.parse(path.read_text())
    out: set[str] = set()
    aliases: set[str] = set()  # names bound to the package itself (import mjx_pick as mp)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module == "mjx_pick":
                for a in node.names:
                    target = public(a.name) or f"mjx_pick.{a.name}"
                    out.add(resolve(target, known))
            elif node.module.startswith("mjx_pick."):
                for a in node.names:
                    out.add(resolve(f"{node.module}.{a.name}", known))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "mjx_pick":  # the facade itself: the interface layer
                    out.add("mjx_pick")
                    aliases.add(a.asname or "mjx_pick")
                elif a.name.startswith("mjx_pick."):
                    out.add(resolve(a.name, known))
                    if a.asname is None:
                        aliases.add("mjx_pick")
    for node in ast.walk(tree):  # mp.evaluate, mjx_pick.core.objects.load_object, ...
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id in aliases:
                target = public(node.attr) or f"mjx_pick.{node.attr}"
                if resolve(target, known) in known:
                    out.add(resolve(target, known))
    return {m for m in out if m in known}


def test_every_module_has_a_layer():
    unknown = []
    for name in modules():
        try:
            layer_of(name)
        except KeyError as err:
            unknown.append(str(err))
    assert not unknown, f"put these modules in a layer's folder: {unknown}"


@pytest.mark.parametrize("name", list(modules()))
def test_imports_only_look_down(name):
    known = modules()
    mine = ORDER.index(layer_of(name))
    upward = sorted(m for m in imported(known[name], known) if ORDER.index(layer_of(m)) > mine)
    assert not upward, f"{name} ({layer_of(name)}) imports {upward}"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def package_of(module: str, known: dict[str, Path]) -> str | None:
    """A module's own package, which its package __init__ may import without a cycle."""
    parent = module.rsplit(".", 1)[0]
    return parent if parent in known and parent != module else None


def test_no_import_cycles():
    known = modules()
    graph = {}
    for name, path in known.items():
        # a package's __init__ handing on its own modules' names is not a cycle of ideas
        deps = {m for m in imported(path, known) if m != name}
        if path.name == "__init__.py":
            deps = {m for m in deps if not m.startswith(name + ".")}
        deps.discard(package_of(name, known))
        graph[name] = deps
    assert not cycles(graph), f"import cycles: {cycles(graph)}"


def test_the_check_sees_every_import_form(tmp_path):
    known = modules()
    src = tmp_path / "m.py"
    src.write_text("def f():\n    from mjx_pick.outputs.reporting import report\n")
    assert imported(src, known) == {"mjx_pick.outputs.reporting"}
    src.write_text("def f():\n    from mjx_pick import sweep\n")  # a public function
    assert imported(src, known) == {"mjx_pick.studies.sweeps"}
    src.write_text("import mjx_pick as mp\nmp.evaluate\n")  # the facade and what it hands on
    assert imported(src, known) == {"mjx_pick", "mjx_pick.studies.evaluation"}
    src.write_text("import mjx_pick.engine.runner\n")
    assert imported(src, known) == {"mjx_pick.engine.runner"}
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]


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
        "search",
        "state",
        "one_pick",
        "worker",
        "replay3d",
        "workfolder",
        "grasp_input",
        "trials_input",
    ),
    "page parts": (
        "page",
        "page.widgets",
        "page.settings_form",
        "page.job_panel",
        "page.replay_view",
    ),
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
