"""The public API: every name in __all__ imports, and nothing private leaks in."""

import inspect

import mjx_pick


def test_public_names_import():
    names = mjx_pick.__all__
    assert set(names) == set(mjx_pick._PUBLIC), "__all__ and the lazy-import table differ"
    assert len(set(names)) == len(names), "duplicate names in __all__"
    assert not [n for n in names if n.startswith("_")], "private names in __all__"
    for name in names:
        if name in mjx_pick._RENAMED:
            continue  # a deprecated old name: test_renamed_names_warn_and_give_the_new_one
        assert hasattr(mjx_pick, name), f"__all__ names {name!r}, which does not import"
        value = getattr(mjx_pick, name)
        # every public name is a class, a function or a module of the package
        assert callable(value) or inspect.ismodule(value), (name, type(value))
        owner = getattr(value, "__module__", getattr(value, "__name__", ""))
        assert owner.startswith("mjx_pick"), f"{name} comes from {owner}, not mjx_pick"


def test_renamed_names_warn_and_give_the_new_one():
    import pytest

    for old, new in mjx_pick._RENAMED.items():
        with pytest.warns(DeprecationWarning, match=f"now mjx_pick.{new}"):
            assert getattr(mjx_pick, old) is getattr(mjx_pick, new)


def test_kernels_install_under_the_package():
    import mjx_pick.kernels.feasibility as f
    import mjx_pick.kernels.grasp as g

    assert f.REASONS[0] == "feasible" and g.FAILURES[0] == "success"


def test_cli_version_names_the_engines(capsys):
    import importlib.metadata

    import pytest

    from mjx_pick import cli

    with pytest.raises(SystemExit) as done:
        cli.main(["--version"])
    assert done.value.code == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"mjx-pick {importlib.metadata.version('mjx-pick')} (")
    assert f"mujoco {importlib.metadata.version('mujoco')}" in line and "jax " in line


def test_no_public_function_shadows_a_module():
    # `import mjx_pick.X as m` must give the module X, never a function of the same name
    import importlib.util

    clash = [n for n in mjx_pick.__all__ if importlib.util.find_spec(f"mjx_pick.{n}")]
    assert not clash, f"public names that are also module names: {clash}"


def test_import_has_no_side_effects():
    # a fresh interpreter: importing the package loads no engine and changes no setting
    import json
    import os
    import subprocess
    import sys

    code = (
        "import json, os, sys; before = dict(os.environ); import mjx_pick; "
        "print(json.dumps({'changed': sorted(k for k in set(before) | set(os.environ) "
        "if before.get(k) != os.environ.get(k)), 'loaded': sorted(m for m in "
        "('mujoco', 'jax', 'matplotlib', 'warp', 'ray') if m in sys.modules)}))"
    )
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    env.pop("DISPLAY", None)  # where the old package set MUJOCO_GL=egl
    got = json.loads(
        subprocess.run(
            [sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True
        ).stdout
    )
    assert got == {"changed": [], "loaded": []}
    # and a public name still loads on first use
    assert mjx_pick.evaluate.__module__ == "mjx_pick.studies.evaluation"
