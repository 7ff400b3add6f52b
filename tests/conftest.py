"""Shared fixtures. Strict numerics: rank promotion raises, warnings are errors (pyproject)."""

import os

os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=4")
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture(scope="session")
def door_opener():
    import mjx_pick

    return mjx_pick.load_asset("door_opener")


@pytest.fixture(scope="session")
def block():
    import mjx_pick

    return mjx_pick.load_asset("block")
