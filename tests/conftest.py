"""Shared fixtures and strict numerics.

Rank promotion raises in every test except those marked ``mjx``: MJX's own code relies
on implicit rank promotion, so tests that trace MJX run under JAX's default. Warnings
are errors (pyproject's filterwarnings).
"""

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=4")
os.environ.setdefault("JAX_PLATFORMS", "cpu")
# the on-disk cache (object preparation, compiled programs) in a folder of this session,
# never the user's own: its processes (CLI tests, GUI jobs) inherit the variable
_CACHE_DIR = tempfile.mkdtemp(prefix="mjx_pick_test_cache.")
os.environ["MJX_PICK_CACHE_DIR"] = _CACHE_DIR
os.environ.pop("MJX_PICK_CACHE", None)
atexit.register(shutil.rmtree, _CACHE_DIR, True)

from mjx_pick.outputs.display import use_offscreen_rendering  # noqa: E402

use_offscreen_rendering()  # the report tests render animations on a headless CI machine

import jax  # noqa: E402
import pytest  # noqa: E402


def pytest_configure(config):
    config.addinivalue_line("markers", "mjx: traces MJX (runs without strict rank promotion)")


@pytest.fixture(autouse=True)
def strict_rank_promotion(request):
    if request.node.get_closest_marker("mjx"):
        yield
        return
    with jax.numpy_rank_promotion("raise"):
        yield


@pytest.fixture(scope="module", autouse=True)
def release_compiled_programs():
    """A test worker runs many files: after each, JAX's compiled programs (MJX's run to
    gigabytes) are dropped, so that a worker's memory does not add them up file after
    file (two workers on a CI machine of a few tens of GB)."""
    yield
    import gc

    jax.clear_caches()
    gc.collect()


@pytest.fixture(scope="session")
def door_opener():
    import mjx_pick

    return mjx_pick.load_asset("door_opener")


@pytest.fixture(scope="session")
def block():
    import mjx_pick

    return mjx_pick.load_asset("block")


@pytest.fixture()
def count_compiles():
    """count_compiles(fn): how many XLA backend compilations running fn() caused."""
    from jax._src import monitoring

    def count(fn) -> int:
        events = []

        def listener(name, secs, **kw):
            if name == "/jax/core/compile/backend_compile_duration":
                events.append(secs)

        monitoring.register_event_duration_secs_listener(listener)
        try:
            fn()
        finally:
            monitoring.unregister_event_duration_listener(listener)
        return len(events)

    return count
