"""The public API: every name in __all__ imports, and nothing private leaks in."""

import inspect

import mjx_pick


def test_public_names_import():
    names = mjx_pick.__all__
    assert len(set(names)) == len(names), "duplicate names in __all__"
    assert not [n for n in names if n.startswith("_")], "private names in __all__"
    for name in names:
        assert hasattr(mjx_pick, name), f"__all__ names {name!r}, which does not import"
        value = getattr(mjx_pick, name)
        # every public name is a class, a function or a module of the package
        assert callable(value) or inspect.ismodule(value), (name, type(value))
        owner = getattr(value, "__module__", getattr(value, "__name__", ""))
        assert owner.startswith("mjx_pick"), f"{name} comes from {owner}, not mjx_pick"


def test_kernels_install_under_the_package():
    import mjx_pick.kernels.feasibility as f
    import mjx_pick.kernels.grasp as g

    assert f.REASONS[0] == "feasible" and g.FAILURES[0] == "none"


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
