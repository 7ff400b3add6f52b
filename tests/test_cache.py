"""The on-disk cache of object preparation (mjx_pick.core.cache) and its CLI.

Every test points MJX_PICK_CACHE_DIR at its own folder. Speed is not timed here
(benchmarks/time_to_answer.py): a hit is checked by the expensive function not being
called again.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import shapely
import trimesh

from mjx_pick.core import cache
from mjx_pick.core import objects as ob

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def cache_dir(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV_DIR, str(folder))
    monkeypatch.delenv(cache.ENV_SWITCH, raising=False)
    monkeypatch.delenv(cache.ENV_MAX_MB, raising=False)
    return folder


@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory):
    """A small concave part (an L of two boxes), mm: CoACD splits it in a second."""
    ell = shapely.Polygon([(0, 0), (40, 0), (40, 10), (10, 10), (10, 30), (0, 30)])
    path = tmp_path_factory.mktemp("mesh") / "ell.stl"
    trimesh.creation.extrude_polygon(ell, 10.0).export(path)
    return path


def load(path):
    return ob.load_object(path, unit="mm", mass_g=20)


def spy(monkeypatch, name):
    """Count the calls of objects.<name> (still computing)."""
    calls = []
    real = getattr(ob, name)

    def counted(*a, **kw):
        calls.append(1)
        return real(*a, **kw)

    monkeypatch.setattr(ob, name, counted)
    return calls


def same_object(a, b):
    assert len(a.pieces) == len(b.pieces)
    for p, q in zip(a.pieces, b.pieces, strict=True):
        assert p.dtype == q.dtype and np.array_equal(p, q)  # bit for bit
    assert shapely.to_wkb(a.polygon) == shapely.to_wkb(b.polygon)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.faces, b.mesh.faces)
    assert np.array_equal(a.inertia_kg_m2, b.inertia_kg_m2) and a.mass_kg == b.mass_kg


def test_cached_mesh_equals_computed_and_skips_the_decomposition(cache_dir, mesh_file, monkeypatch):
    monkeypatch.setenv(cache.ENV_SWITCH, "0")
    computed = load(mesh_file)
    wall = computed.wall_height_mm(2.0, 8.0)
    assert not cache_dir.exists()  # bypassed: nothing written
    monkeypatch.delenv(cache.ENV_SWITCH)
    coacd, outline = spy(monkeypatch, "_coacd_pieces"), spy(monkeypatch, "_mesh_outline")
    first = load(mesh_file)
    assert (len(coacd), len(outline)) == (1, 1)
    second = load(mesh_file)
    assert (len(coacd), len(outline)) == (1, 1), "the second load computed again"
    same_object(computed, first)
    same_object(computed, second)
    # a band's outline: computed once, then read
    band = second.band_outline(2.0, 6.0)
    assert len(outline) == 2
    assert shapely.to_wkb(load(mesh_file).band_outline(2.0, 6.0)) == shapely.to_wkb(band)
    assert len(outline) == 2
    # a band's side wall (mesh sections): the same from the cache, computed or read
    assert first.wall_height_mm(2.0, 8.0) == wall == load(mesh_file).wall_height_mm(2.0, 8.0)


def test_every_parameter_that_changes_the_result_is_in_the_key(cache_dir, mesh_file, tmp_path):
    load(mesh_file)
    other = ob.object_from_mesh(mesh_file, unit="mm", mass_g=20, coacd_threshold=0.08)
    moved = tmp_path / "moved.stl"
    m = trimesh.load(mesh_file)
    m.apply_scale(1.5)
    m.export(moved)
    bigger = load(moved)
    assert len(list((cache_dir / "objects").glob("mesh-*.npz"))) == 3
    assert bigger.height_mm > 1.4 * other.height_mm


def _entry(cache_dir) -> Path:
    (entry,) = (cache_dir / "objects").glob("mesh-*.npz")
    return entry


def test_a_corrupt_entry_warns_once_and_is_recomputed(cache_dir, mesh_file, monkeypatch):
    good = load(mesh_file)
    entry = _entry(cache_dir)
    data = bytearray(entry.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 64] = b"\0" * 64  # damage inside the archive
    entry.write_bytes(bytes(data))
    coacd = spy(monkeypatch, "_coacd_pieces")
    with pytest.warns(cache.CacheWarning, match="unreadable"):
        again = load(mesh_file)
    assert len(coacd) == 1
    same_object(good, again)
    load(mesh_file)  # replaced by a good entry: read, no warning (warnings are errors)
    assert len(coacd) == 1
    entry.write_bytes(b"not a zip file")  # said once already in this process: quiet now
    same_object(good, load(mesh_file))
    assert len(coacd) == 2


def test_an_entry_of_another_version_warns_and_is_replaced(cache_dir, mesh_file, monkeypatch):
    real = cache.versions()
    monkeypatch.setattr(cache, "versions", lambda: {**real, "coacd": "0.0.1"})
    old = load(mesh_file)
    monkeypatch.setattr(cache, "versions", lambda: real)
    coacd = spy(monkeypatch, "_coacd_pieces")
    with pytest.warns(cache.CacheWarning, match="other versions"):
        new = load(mesh_file)
    assert len(coacd) == 1  # not used: computed
    same_object(old, new)
    load(mesh_file)
    assert len(coacd) == 1  # this version's entry now


def test_an_unwritable_folder_warns_once_and_still_answers(tmp_path, mesh_file, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    folder = blocker / "cache"  # cannot be created: its parent is a file (root or not)
    monkeypatch.setenv(cache.ENV_DIR, str(folder))
    monkeypatch.delenv(cache.ENV_SWITCH, raising=False)
    with pytest.warns(cache.CacheWarning, match="cannot be written") as said:
        a = load(mesh_file)
        b = load(mesh_file)
    assert len(said) == 1
    same_object(a, b)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_warns_once(tmp_path, mesh_file, monkeypatch):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    monkeypatch.setenv(cache.ENV_DIR, str(folder))
    try:
        with pytest.warns(cache.CacheWarning, match="cannot be written") as said:
            load(mesh_file)
            load(mesh_file)
        assert len(said) == 1
    finally:
        folder.chmod(0o755)


def test_least_recently_used_entries_are_evicted(tmp_path):
    store = cache.Store(tmp_path / "objects", limit=0)
    block = {"a": np.zeros(100_000, np.uint8)}
    assert not store.put("zero", {}, block)  # limit 0: nothing fits
    store.limit = 1 << 30
    for name in ("one", "two", "three"):
        store.put(name, {"n": name}, block)
    size = store.size() // 3
    for age, name in ((300, "one"), (200, "two"), (100, "three")):  # one is the oldest
        t = os.path.getmtime(store.path(name, {"n": name})) - age
        os.utime(store.path(name, {"n": name}), (t, t))
    assert store.get("one", {"n": "one"}) is not None  # a read makes it the newest
    store.limit = 3 * size + size // 2
    store.put("four", {"n": "four"}, block)  # four entries do not fit: the LRU one goes
    left = sorted(p.name.split("-")[0] for p in store.folder.glob("*.npz"))
    assert left == ["four", "one", "three"]
    assert store.size() <= store.limit


def test_an_entry_larger_than_the_limit_is_not_stored(tmp_path):
    store = cache.Store(tmp_path / "objects", limit=1000)
    assert not store.put("big", {}, {"a": np.zeros(10_000, np.uint8)})
    assert store.get("big", {}) is None


WRITER = textwrap.dedent(
    """
    import sys
    from pathlib import Path

    import numpy as np

    from mjx_pick.core import cache

    store = cache.Store(Path(sys.argv[1]), limit=1 << 30)
    value = {"a": np.arange(2_000_000, dtype=np.int64)}
    for _ in range(15):
        store.put("race", {"k": 1}, value)
        got = store.get("race", {"k": 1})
        assert got is None or np.array_equal(got["a"], value["a"]), "a partial entry"
    """
)


def test_concurrent_writers_leave_a_valid_entry(tmp_path):
    folder = tmp_path / "objects"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [
        subprocess.Popen([sys.executable, "-c", WRITER, str(folder)], env=env) for _ in range(2)
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    store = cache.Store(folder, limit=1 << 30)
    got = store.get("race", {"k": 1})
    assert np.array_equal(got["a"], np.arange(2_000_000, dtype=np.int64))
    assert not list(folder.glob("*.tmp")), "temporary files left behind"


def test_cli_cache_info_and_clear(cache_dir, mesh_file, capsys):
    from mjx_pick import cli

    load(mesh_file)
    (cache_dir / "jax").mkdir()
    (cache_dir / "jax" / "prog-cache").write_bytes(b"x" * 2048)
    assert cli.main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(cache_dir) in out and "1 entries" in out and "1 files" in out
    assert cache.ENV_DIR in out and "mjx-pick cache clear" in out
    assert cli.main(["cache", "clear"]) == 0
    assert "1 object results, 1 compiled-program files" in capsys.readouterr().out
    assert cache.info()["objects"]["entries"] == 0 and not (cache_dir / "jax").exists()


def test_cli_no_cache_reads_and_writes_nothing(cache_dir, monkeypatch, tmp_path, capsys):
    from mjx_pick import cli

    monkeypatch.setenv(cache.ENV_SWITCH, "1")  # restored after: --no-cache sets it to 0
    out = tmp_path / "picks"
    assert cli.main(["picks", "block", "--n", "4", "--out", str(out), "--no-cache"]) == 0
    assert os.environ[cache.ENV_SWITCH] == "0"
    assert not cache_dir.exists()
    assert cli.main(["cache", "info"]) == 0
    assert "(off (MJX_PICK_CACHE=0))" in capsys.readouterr().out


COMPILED = textwrap.dedent(
    """
    import jax
    import mjx_pick as mp
    from mjx_pick.engine import compiled, runner
    print(jax.config.jax_compilation_cache_dir)  # importing sets nothing
    scene = mp.build_scene(mp.load_object("block"), mp.load_gripper("robotiq-2f85"))
    runner.Runner("mujoco").make(scene, mp.GraspConfig())  # a backend running JAX programs
    print(jax.config.jax_compilation_cache_dir)
    print(jax.config.jax_persistent_cache_min_compile_time_secs == compiled.MIN_COMPILE_S)
    """
)


@pytest.mark.parametrize("switch", ["1", "0"])
def test_the_engine_turns_on_the_compilation_cache_unless_bypassed(cache_dir, switch):
    env = {**os.environ, "PYTHONPATH": str(ROOT), cache.ENV_SWITCH: switch}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    lines = subprocess.run(
        [sys.executable, "-c", COMPILED], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert lines[0] == "None"
    if switch == "1":
        assert lines[1:] == [str(cache_dir / "jax"), "True"]
    else:
        assert lines[1] == "None"


# ------------------------------------------------------------ an MJCF gripper's close

LINKAGE = "robotiq-2f85-linkage"


def same_fields(a, b) -> None:
    """Two dataclass values equal field by field, arrays bit for bit (dtype and shape too)."""
    import dataclasses

    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert np.array_equal(x, y, equal_nan=True), f.name
        else:
            assert type(x) is type(y) and x == y, f.name


def model_values(m) -> dict:
    """Every array and number of a compiled MjModel and of its option, statistic and
    visual structs, by name."""
    out = {}
    groups = [("", m)] + [(f"{g}.", getattr(m, g)) for g in ("opt", "stat", "vis")]
    for prefix, obj in groups:
        for name in dir(obj):
            value = getattr(obj, name) if not name.startswith("_") else None
            if isinstance(value, np.ndarray | int | float):
                out[prefix + name] = np.asarray(value)
    return out


def same_model(a, b) -> None:
    va, vb = model_values(a), model_values(b)
    assert va.keys() == vb.keys()
    differ = [k for k in va if not np.array_equal(va[k], vb[k], equal_nan=va[k].dtype.kind == "f")]
    assert not differ, differ


def test_an_mjcf_grippers_close_is_read_back_bit_for_bit(cache_dir, monkeypatch):
    """The linkage's quasi-static close (seconds of MuJoCo C steps in every process that
    loads it) is computed once and then read from the cache: its Kinematics, the scene
    built on it (model arrays, index, MJCF text) and a short run's labels are those of
    a close computed without the cache."""
    import mjx_pick as mp
    from mjx_pick.core import mjcf_gripper
    from mjx_pick.engine.backend import make_backend
    from mjx_pick.engine.inputs import make_inputs

    monkeypatch.setenv(cache.ENV_SWITCH, "0")
    mjcf_gripper.characterise.cache_clear()
    grasp = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
    block = mp.load_object("block")
    gripper = mp.load_gripper(LINKAGE)

    def scene_and_labels():
        scene = mp.build_scene(block, gripper, None, None, grasp)
        checker = mp.FeasibilityChecker(block, gripper, grasp=grasp)
        picks = checker.batch(
            np.arange(2), np.zeros(2), np.array([0.0, 2.0]), np.zeros(2), mode="user"
        )
        backend = make_backend("mujoco", scene, grasp, batch_size=2)
        out, _ = backend.run(make_inputs(scene, grasp, picks))
        return scene, out

    computed = mjcf_gripper.characterise(gripper.mjcf)
    fresh, fresh_out = scene_and_labels()
    assert not cache_dir.exists()  # bypassed: nothing written
    monkeypatch.delenv(cache.ENV_SWITCH)
    calls = []
    real = mjcf_gripper._close
    monkeypatch.setattr(mjcf_gripper, "_close", lambda *a: calls.append(1) or real(*a))
    mjcf_gripper.characterise.cache_clear()
    same_fields(computed, mjcf_gripper.characterise(gripper.mjcf))
    assert len(calls) == 1
    mjcf_gripper.characterise.cache_clear()  # a new process, as far as the close goes
    read = mjcf_gripper.characterise(gripper.mjcf)
    assert len(calls) == 1, "the second close was computed again"
    same_fields(computed, read)
    assert computed.drive_map() == read.drive_map()
    scene, out = scene_and_labels()
    assert len(calls) == 1
    same_model(fresh.model, scene.model)
    assert scene.index == fresh.index and scene.xml == fresh.xml
    assert out.keys() == fresh_out.keys()
    for k in out:
        assert np.array_equal(out[k], fresh_out[k], equal_nan=True), k


def test_a_changed_gripper_is_another_close_and_a_corrupt_one_is_recomputed(cache_dir, monkeypatch):
    import dataclasses

    import mjx_pick as mp
    from mjx_pick.core import mjcf_gripper

    mjcf = mp.load_gripper(LINKAGE).mjcf
    stiffer = dataclasses.replace(mjcf, actuator_kp=2.0 * (mjcf.actuator_kp or 1.0))
    mjcf_gripper.characterise.cache_clear()
    mjcf_gripper.characterise(mjcf)
    mjcf_gripper.characterise(stiffer)
    entries = sorted((cache_dir / "objects").glob("gripper_close-*.npz"))
    assert len(entries) == 2  # the servo's override is part of the compiled model
    good = mjcf_gripper.characterise(mjcf)
    for entry in entries:
        entry.write_bytes(b"not a zip file")
    mjcf_gripper.characterise.cache_clear()
    with pytest.warns(cache.CacheWarning, match="unreadable"):
        again = mjcf_gripper.characterise(mjcf)
    same_fields(good, again)
