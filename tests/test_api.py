"""The public API: every name in __all__ imports, and nothing private leaks in."""

import mjx_pick


def test_public_names_import():
    for name in mjx_pick.__all__:
        assert getattr(mjx_pick, name) is not None, name
    assert sorted(mjx_pick.__all__) == mjx_pick.__all__ or len(set(mjx_pick.__all__)) == len(
        mjx_pick.__all__
    )


def test_kernels_install_under_the_package():
    import mjx_pick.kernels.feasibility as f
    import mjx_pick.kernels.grasp as g

    assert f.REASONS[0] == "feasible" and g.FAILURES[0] == "none"
