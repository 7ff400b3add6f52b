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
# never the user's own: its processes (CLI tests, GUI jobs) inherit the variable. One
# folder for the whole run: made by the process that starts it (xdist's controller, or
# the only process) before any worker starts, so the workers inherit it through the
# environment and share what one of them prepared or compiled; removed by that process
# alone. Sharing is safe: object entries are written to a temporary file and renamed
# (core/cache.py), JAX's programs under its file lock (a size limit is set).
_SHARED = "MJX_PICK_TEST_SESSION_CACHE"
if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get(_SHARED):
    _CACHE_DIR = os.environ[_SHARED]
else:
    _CACHE_DIR = tempfile.mkdtemp(prefix="mjx_pick_test_cache.")
    os.environ[_SHARED] = _CACHE_DIR
    atexit.register(shutil.rmtree, _CACHE_DIR, True)
os.environ["MJX_PICK_CACHE_DIR"] = _CACHE_DIR
os.environ.pop("MJX_PICK_CACHE", None)

from mjx_pick.outputs.display import use_offscreen_rendering  # noqa: E402

use_offscreen_rendering()  # the report tests render animations on a headless CI machine

import jax  # noqa: E402
import pytest  # noqa: E402

from mjx_pick.engine import compiled  # noqa: E402

# JAX's compiled programs kept on disk from the first compile on (the engine turns this
# on when it builds a backend; programs compiled before that, or traced by tests
# themselves, were compiled anew in every worker and again after each file's
# release_compiled_programs)
compiled.use_persistent_cache()


def pytest_configure(config):
    config.addinivalue_line("markers", "mjx: traces MJX (runs without strict rank promotion)")


# Seconds each long file takes alone on one core (measured: pytest --durations=0, one
# process, a 2-core machine); the rest take under 20 s each. `--dist loadfile` hands out
# whole files; xdist orders them by number of tests, which put several of the longest
# (few, slow MJX tests) last, where they left one worker running alone at the end. Longest
# first, the files that end a run are short. Update a figure when a file's time changes much.
FILE_SECONDS = {
    "tests/test_backend_warp.py": 250,
    "tests/test_calibrate.py": 175,
    "tests/test_gui.py": 160,
    "tests/test_third_routes.py": 160,  # CPU s under load; its CLI runs import JAX each
    "tests/test_backends.py": 140,
    "tests/test_variants.py": 115,
    "tests/test_warp_direct.py": 170,
    "tests/test_physics.py": 60,  # the rubber pad's reference LP built sparse (was 85)
    "tests/test_cluster.py": 75,
    "tests/test_scale.py": 75,
    "tests/test_gripper_mjcf.py": 50,  # the same (was 65)
    "tests/test_gui_parts.py": 65,
    "tests/test_readme.py": 60,
    "tests/test_gui_routes.py": 150,  # 20 Chromium tests (measured alone, 2026-11-28)
    "tests/test_gui_replay.py": 80,  # with the tilted grasp run's replay
    "notebooks/throughput.ipynb": 40,
    "notebooks/calibration.ipynb": 30,
    "tests/test_mesh_import.py": 40,
    "tests/test_cache.py": 45,
    "tests/test_session.py": 30,
    "tests/test_trials.py": 25,
    "tests/test_pinned.py": 25,
    "tests/test_simulation.py": 20,
}


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadfile`, longest file first (FILE_SECONDS); other modes as xdist has them."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class LongestFileFirst(LoadFileScheduling):
        def _assign_work_unit(self, node):
            # a stable sort: files of equal (unlisted) length keep xdist's order
            for scope in sorted(self.workqueue, key=lambda s: -FILE_SECONDS.get(s, 0)):
                self.workqueue.move_to_end(scope)
            super()._assign_work_unit(node)

    return LongestFileFirst(config, log)


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


@pytest.fixture()
def hull_pieces(monkeypatch):
    """A mesh's convex hull as its one collision piece instead of CoACD's pieces, for
    tests that do not check the pieces: CoACD takes 5-40 s per mesh on a 2-core CPU.

    The object cache is off meanwhile: its key does not know the stand-in, so it would
    hand a later test of the same worker (a GUI upload of the same mesh, say) the hull,
    or this test the pieces CoACD made for an earlier one."""
    import numpy as np

    from mjx_pick.core import cache, objects

    def hull(mesh, threshold):
        return (np.asarray(mesh.convex_hull.vertices, dtype=float),)

    monkeypatch.setattr(objects, "_coacd_pieces", hull)
    monkeypatch.setenv(cache.ENV_SWITCH, "0")


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
