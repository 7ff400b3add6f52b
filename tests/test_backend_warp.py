"""The MJX-Warp backend's CPU-testable parts: backend choice and its errors, buffer sizing,
and slot refill (run with MJX's JAX implementation, the program Warp runs too).

CI has no GPU and no warp-lang; the GPU figures come from benchmarks/throughput.py.
With warp-lang installed, MJX_PICK_WARP_CPU=1 runs the Warp backend itself on the CPU
(LLVM-compiled kernels, minutes): the last test.
"""

import dataclasses
import importlib.metadata
import importlib.util
import os

import mujoco
import mujoco.batch
import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import devices, warp_buffers
from mjx_pick.engine import warp_backend as bw
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.kernels import grasp as gk

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=10.0, hold_s=0.1)


@pytest.fixture()
def block_scene(block):
    return mp.build_scene(block, mp.GripperSpec(), grasp=SHORT)


@pytest.fixture()
def mjx_scene(block):
    """The block at the physics MJX's JAX engine runs (the 'mjx' backend's)."""
    contact, solver = mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
    return mp.build_scene(block, mp.GripperSpec(), contact, solver, grasp=SHORT)


@pytest.fixture()
def fresh_probe():
    """warp_problem() is cached per process: clear it around a test that fakes the
    machine."""
    devices.warp_problem.cache_clear()
    yield
    devices.warp_problem.cache_clear()


# --------------------------------------------------------------------------- choice
def test_backend_names_and_options(block_scene):
    with pytest.raises(mp.ConfigError, match="'auto', 'warp', 'mjx-warp', 'mjx', 'mujoco'"):
        make_backend("gpu", block_scene, SHORT, batch_size=4)
    with pytest.raises(mp.ConfigError, match="takes no options"):
        make_backend("mujoco", block_scene, SHORT, batch_size=4, refill=True)


def test_warp_without_gpu_is_a_clear_error(block_scene, fresh_probe, monkeypatch):
    monkeypatch.delenv(devices.ALLOW_CPU_ENV, raising=False)
    if devices.nvidia_gpus():
        pytest.skip("this machine has a CUDA GPU")
    with pytest.raises(mp.ConfigError, match=r'no NVIDIA \(CUDA\) GPU.*pip install "\.\[gpu\]"'):
        make_backend("mjx-warp", block_scene, SHORT, batch_size=4)
    # auto falls back to the C engine, quietly: warp is not even imported
    assert make_backend("auto", block_scene, SHORT, batch_size=4).name == "mujoco"


def _fake_gpu(monkeypatch, warp_spec, version="1.18.0"):
    monkeypatch.delenv(devices.ALLOW_CPU_ENV, raising=False)
    monkeypatch.setattr(devices, "nvidia_gpus", lambda: ["cuda:0"])
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        devices.importlib.util,
        "find_spec",
        lambda name, *a: warp_spec if name == "warp" else find_spec(name, *a),
    )
    real_version = importlib.metadata.version
    monkeypatch.setattr(
        devices.importlib.metadata,
        "version",
        lambda name: version if name == "warp-lang" else real_version(name),
    )


def test_gpu_without_warp_lang_names_the_extra(block_scene, fresh_probe, monkeypatch):
    _fake_gpu(monkeypatch, warp_spec=None)
    with pytest.raises(
        mp.ConfigError, match=r'warp-lang is not installed.*pip install "\.\[gpu\]"'
    ):
        make_backend("mjx-warp", block_scene, SHORT, batch_size=4)
    # auto on a GPU without warp-lang: the C engine (faster there than MJX's JAX physics)
    devices.warp_problem.cache_clear()
    assert make_backend("auto", block_scene, SHORT, batch_size=4).name == "mujoco"


def test_wrong_warp_version_is_named(block_scene, fresh_probe, monkeypatch):
    pin = devices.warp_pin()
    if pin is None:
        pytest.skip("mujoco-mjx declares no warp-lang pin")
    _fake_gpu(monkeypatch, warp_spec=object(), version="0.1.0")
    with pytest.raises(mp.ConfigError, match=rf"warp-lang 0\.1\.0 is installed.*warp-lang{pin}"):
        make_backend("mjx-warp", block_scene, SHORT, batch_size=4)


def test_gpu_extra_pins_warp_like_mujoco_mjx():
    pin = devices.warp_pin()  # e.g. "==1.18.0"
    if pin is None:
        pytest.skip("mujoco-mjx declares no warp-lang pin")
    import tomllib
    from pathlib import Path

    from packaging.requirements import Requirement

    pyproject = Path(__file__).parents[1] / "pyproject.toml"
    extras = tomllib.loads(pyproject.read_text())["project"]["optional-dependencies"]
    (req,) = [Requirement(r) for r in extras["gpu"] if r.startswith("warp-lang")]
    mjx_version = pin.lstrip("=")
    assert mjx_version in req.specifier, f"gpu extra {req} excludes mujoco-mjx's {pin}"


# --------------------------------------------------------------------------- buffers
def test_streams_warp_does_not_own_stay_registered(monkeypatch):
    # Warp's registry of CUDA streams has no count: freeing any wrapper of XLA's stream
    # unregistered it under a newer wrapper's graph capture (GPU evidence:
    # benchmarks/probes/warp_stream_repro.py). Here a stand-in for warp.Stream, as CI has no warp.
    import sys
    import types

    freed = []

    class Stream:
        def __init__(self, owner):
            self.owner = owner

        def __del__(self):
            freed.append(self.owner)

    monkeypatch.setitem(sys.modules, "warp", types.SimpleNamespace(Stream=Stream))
    bw.keep_xla_stream_registrations()
    bw.keep_xla_stream_registrations()  # idempotent: one layer, not two
    Stream(owner=False)  # freed at once (CPython counts references)
    Stream(owner=True)
    assert freed == [True]


def test_buffer_margin_and_sizes():
    contacts, rows = bw.buffer_margin(15, 60)
    assert contacts >= 1.5 * 15 and contacts % 4 == 0
    assert rows >= 2 * 60 and rows % 8 == 0
    assert bw.buffer_margin(0, 0) == (4, 16)
    b = bw.BufferSizes(contacts, rows, 15, 60, 32)
    assert b.naconmax(1000) == contacts * 1000  # Warp's contact buffer: all worlds
    assert b.grown(contacts=True, rows=False) == bw.BufferSizes(2 * contacts, rows, 15, 60, 32)
    assert b.grown(contacts=False, rows=True).rows == 2 * rows
    with pytest.raises(mp.ConfigError, match="buffers.rows"):
        bw.BufferSizes(8, 0)
    with pytest.raises(mp.ConfigError, match="buffers.contacts"):
        bw.BufferSizes(2.5, 8)


def test_counting_batch_sees_every_step():
    # a box dropped onto a plane: its contacts appear at one physics step and change
    # with the bounce; the counting batch must see the same maxima as stepping one
    # MjData step by step, though the backend asks for several substeps per call
    xml = """<mujoco><option timestep="0.002"/><worldbody>
      <geom type="plane" size="1 1 .1"/>
      <body pos="0 0 .06"><freejoint/><geom type="box" size=".05 .03 .02"/></body>
      <body pos=".3 0 .5"><freejoint/><geom type="sphere" size=".02"/></body>
    </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    b = warp_buffers._CountingBatch(mujoco.batch.Batch(model, nsim=2, nthread=1))
    qpos = b.bind("qpos")
    qpos[1, 2] = 0.3  # the second simulation's box starts higher
    for _ in range(60):
        b.step(nstep=5)
    for sim in range(2):
        data = mujoco.MjData(model)
        data.qpos[2] = 0.3 if sim == 1 else data.qpos[2]
        most_con = most_efc = 0
        for _ in range(300):
            mujoco.mj_step(model, data)
            most_con, most_efc = max(most_con, data.ncon), max(most_efc, data.nefc)
        assert (b.max_ncon[sim], b.max_nefc[sim]) == (most_con, most_efc)
    assert b.max_ncon.min() > 0


def test_size_buffers_measures_the_scene(block_scene):
    picks = pp.generate_normal(block_scene.object, mp.GripperSpec(), 3, seed=0, grasp=SHORT)
    inputs = make_inputs(block_scene, SHORT, picks)
    ncon, nefc = bw.measure_buffers(block_scene, SHORT, inputs, nthread=1)
    assert ncon.shape == nefc.shape == (3,)
    # the block rests on the table from the start, and the pads touch it in the close
    assert (ncon > 0).all() and (nefc >= ncon).all()
    sizes = bw.size_buffers(block_scene, SHORT, inputs, nthread=1)
    assert (sizes.measured_contacts, sizes.measured_rows) == (ncon.max(), nefc.max())
    assert (sizes.contacts, sizes.rows) == bw.buffer_margin(ncon.max(), nefc.max())
    assert sizes.sample == 3


def test_default_sizing_is_measured_once_then_read_from_the_cache(
    block_scene, tmp_path, monkeypatch
):
    from mjx_pick.core import cache

    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "cache"))
    monkeypatch.delenv(cache.ENV_SWITCH, raising=False)
    measured = []
    real = warp_buffers.measure_buffers

    def counting(*args, **kwargs):
        measured.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(warp_buffers, "measure_buffers", counting)
    first = bw.size_buffers(block_scene, SHORT, n_sample=2, nthread=1)
    again = bw.size_buffers(block_scene, SHORT, n_sample=2, nthread=1)
    assert measured == [1] and first == again and first.sample == 2
    # another procedure is another measurement
    longer = dataclasses.replace(SHORT, hold_s=0.2)
    bw.size_buffers(block_scene, longer, n_sample=2, nthread=1)
    assert measured == [1, 1]
    monkeypatch.setenv(cache.ENV_SWITCH, "0")  # bypassed: measured again
    assert bw.size_buffers(block_scene, SHORT, n_sample=2, nthread=1) == first
    assert len(measured) == 3


# --------------------------------------------------------------------------- refill
def test_small_run_gets_a_small_pool(mjx_scene):
    backend = make_backend("mjx", mjx_scene, SHORT, batch_size=8192, refill=True)
    n_dev = len(backend.devices)
    assert backend.pool_size(200) == 256 * n_dev  # not 8192 padded simulations
    assert backend.pool_size(10**6) == backend.batch_size
    with pytest.raises(ValueError, match="ticks_per_call"):
        make_backend("mjx", mjx_scene, SHORT, batch_size=8, ticks_per_call=0)


@pytest.mark.mjx
def test_refill_reassembles_in_order_and_equals_a_run_without_refill(mjx_scene, count_compiles):
    # 10 picks through a pool of 4 slots (one per CPU device): slots are refilled as
    # picks end -- pick 1 blows up at once, so its slot takes the next pick long before
    # the others end -- and the results come back in pick-point order, bit for bit those
    # of the same program with every pick in a slot of its own from start to end
    picks = pp.generate_normal(mjx_scene.object, mp.GripperSpec(), 10, seed=0, grasp=SHORT)
    inputs = make_inputs(mjx_scene, SHORT, picks)
    inputs.qpos0[1, mjx_scene.index.object_qpos + 2] = np.inf
    backend = make_backend("mjx", mjx_scene, SHORT, batch_size=4, refill=True, ticks_per_call=9)
    out, traces = backend.run(inputs)
    assert traces is None
    stats = backend.pool_stats
    slots_per_device = 4 // len(backend.devices)
    assert stats.picks == 10 and stats.rounds * 9 * slots_per_device == stats.slot_ticks
    assert 0 < stats.occupancy <= 1
    # 10 picks never fit in 4 slots at once: without refill they would take 3 passes
    # of full-length picks (3 x n_ticks per slot); with it each slot runs its picks
    # back to back, each only to its end
    assert stats.slot_ticks < 3 * SHORT.n_ticks() * 4
    # each pick alone: a queue of the same length (so the same compiled program, no
    # second compile) that holds the pick first and then only copies of pick 1, which
    # blow up at once. The first row of a queue starts in a fresh slot at the first
    # round, whichever device's share it is in, and runs there to its end. Each device
    # runs its own share of the queue (its contiguous 12 / n_dev rows) and nothing
    # passes between devices, so one queue holds a pick alone at the head of every
    # device's share: 3 runs on the 4 CPU devices instead of 10
    alone = {key: np.empty_like(value) for key, value in out.items()}
    heads = np.arange(0, 12, 12 // len(backend.devices))  # each share's first row

    def each_alone():
        for first in range(0, 10, len(heads)):
            ids = np.arange(first, min(first + len(heads), 10))
            rows = np.ones(12, int)
            rows[heads[: len(ids)]] = ids
            queue, _ = backend.run(inputs.take(rows))
            for key in alone:
                alone[key][ids] = queue[key][heads[: len(ids)]]

    assert count_compiles(each_alone) == 0
    for key in out:
        np.testing.assert_array_equal(out[key], alone[key], err_msg=key)
    assert out["diverged"][1] and not out["diverged"][[0, 2, 3]].any()
    assert np.isnan(out["score"][1])
    # the C engine flags the same blow-up (labels of two engines are compared at full
    # size on a GPU: benchmarks/throughput.py, benchmarks/agreement.py)
    c, _ = make_backend("mujoco", mjx_scene, SHORT, batch_size=10).run(inputs)
    np.testing.assert_array_equal(out["diverged"], c["diverged"])


@pytest.mark.mjx
def test_a_new_backend_on_the_same_scene_runs_the_program_the_process_compiled(
    mjx_scene, count_compiles
):
    # the GUI's next job, a notebook's next evaluate: a new backend for the same scene,
    # procedure and pool settings runs the program compiled before in the process (the
    # same shapes as the refill test above, which in one process compiled it already)
    picks = pp.generate_normal(mjx_scene.object, mp.GripperSpec(), 10, seed=0, grasp=SHORT)
    inputs = make_inputs(mjx_scene, SHORT, picks)

    def backend(scene=mjx_scene):
        return make_backend("mjx", scene, SHORT, batch_size=4, refill=True, ticks_per_call=9)

    first, _ = backend().run(inputs)
    again, second = backend(), {}
    assert count_compiles(lambda: second.update(again.run(inputs)[0])) == 0
    assert again.stats.compile_s == 0
    for key in first:
        np.testing.assert_array_equal(first[key], second[key], err_msg=key)
    # another model is another program
    contact = mp.ContactParams.differentiable(mp.ContactParams(pad_friction=0.3))
    other = mp.build_scene(
        mjx_scene.object, mp.GripperSpec(), contact, mjx_scene.solver, grasp=SHORT
    )
    assert backend(other).program_identity() != again.program_identity()


@pytest.mark.mjx
def test_pool_shrinks_in_the_tail_and_keeps_each_picks_state(mjx_scene):
    # one device, 8 slots, 12 picks: once the queue is empty and at most 4 slots are
    # live, they move to a pool of 4. The picks are chosen so that their outcome does
    # not hang on rounding (XLA's CPU arithmetic differs a little with the batch shape,
    # so a pool of 4 is not bit-for-bit a pool of 8; on the GPU each Warp world is its
    # own thread): a centred grasp at friction 0.9 that holds to the end, and the same
    # grasp with the object moved 0.2 m away, where the pads close on air and the pick
    # ends early (no contact). A slot moved with another slot's state would swap a
    # held pick with an empty one.
    import jax

    from mjx_pick.engine.pool import shrink_sizes

    assert shrink_sizes(8, 2) == (8, 4, 2) and shrink_sizes(8, 5) == (8, 4, 2, 1)
    assert shrink_sizes(6, 3) == (6, 3) and shrink_sizes(8, 0) == (8,)
    # never below the smallest pool worth its own program
    assert shrink_sizes(8192, 3, 4096) == (8192, 4096) and shrink_sizes(2048, 3, 4096) == (2048,)
    checker = pp.FeasibilityChecker(mjx_scene.object, mp.GripperSpec(), grasp=SHORT)
    picks = checker.batch(np.arange(1), [0.0], [0.0], [0.0], "user")  # centred
    inputs = make_inputs(mjx_scene, SHORT, picks.take(np.zeros(12, int)), {"pad_friction": 0.9})
    air = np.array([1, 3, 4, 6, 7, 9])  # the long picks come last: a tail of 4+ live slots
    inputs.qpos0[air, mjx_scene.index.object_qpos] += 0.2
    held = np.setdiff1d(np.arange(12), air)
    one = jax.devices("cpu")[:1]
    backend = make_backend(
        "mjx",
        mjx_scene,
        SHORT,
        batch_size=8,
        devices=one,
        refill=True,
        ticks_per_call=10,
        shrink_levels=1,
    )
    backend.POOL_QUANTUM = 8
    backend.SHRINK_MIN_SLOTS = 1  # a pool of 8 that shrinks: the tail's logic at CPU size
    shrunk = backend.run(inputs)[0]
    st1 = dataclasses.replace(backend.pool_stats)
    # the same picks without shrinking, from the same compiled program (a queue of 16
    # rows either way): four more held picks at the end of the queue keep at least 5
    # slots live until each of the 12 has ended -- they start after all of them and
    # last as long as the longest -- so the pool stays at 8 slots while any of the 12
    # runs; their own results are not used (measured: the 12 results are bit for bit
    # those of a pool built with shrink_levels=0, a program of its own to compile)
    queue = np.concatenate([np.arange(12), held[:4]])
    full = backend.run(inputs.take(queue))[0]
    full = {key: value[:12] for key, value in full.items()}
    assert full["success"][held].all() and (full["failure"][air] == gk.Outcome.NO_CONTACT).all()
    for key in ("success", "failure", "diverged"):
        np.testing.assert_array_equal(shrunk[key], full[key], err_msg=key)
    for key in ("score", "t_reached_s"):
        np.testing.assert_allclose(shrunk[key], full[key], atol=2e-3, err_msg=key)
    # the held picks' largest rotation is a fraction of a degree set by contact
    # transients, where the batch shape's rounding shows: measured 0.830 deg in pools of
    # 8, 0.664 in a pool of 4 (every held pick, bit for bit), 0.732 in a pool of 2
    np.testing.assert_allclose(shrunk["phi_max_deg"], full["phi_max_deg"], atol=0.25)
    # the shrunk pool stepped fewer idle slots for the same picks: without shrinking
    # they take as many rounds (a pick's ticks do not depend on its pool), all of 8 slots
    assert st1.picks == 12 and st1.slot_ticks < st1.rounds * 8 * 10


def test_device_threads_run_shares_side_by_side_in_pick_order(block_scene):
    # the multi-GPU runner's logic with stand-in backends (CI has one CPU and no GPU;
    # the 2-GPU figure is in RESULTS.md): contiguous shares, run at the same time --
    # each stand-in waits at a barrier for the other, so running them one after the
    # other would time out -- and results, diagnostics and stats merged in pick order
    import threading

    from mjx_pick.engine.backend import RunStats
    from mjx_pick.engine.pool import DeviceThreads, Diagnostics, PoolStats

    barrier = threading.Barrier(2, timeout=20)

    class StandIn:
        name, refill, batch_size = "warp", True, 8

        def __init__(self, device):
            self.scene, self.grasp, self.devices = block_scene, SHORT, [device]
            self.device = "cpu"
            self.stats, self.pool_stats = RunStats(), PoolStats()

        def pool_size(self, n):
            return min(n, 8)

        def run(self, inputs, record=False):
            barrier.wait()
            n = len(inputs)
            self.stats.compile_s += 1.0
            self.stats.run_s += 0.5
            self.pool_stats.picks += n
            x = inputs.qpos0[:, 0]
            self.last_diagnostics = Diagnostics(*(np.full(n, self.devices[0]),) * 3)
            return {"x": x, "device": np.full(n, self.devices[0])}, None

    with pytest.raises(ValueError, match=">= 2"):
        DeviceThreads([StandIn(0)])
    both = DeviceThreads([StandIn(0), StandIn(1)])
    assert both.shares(11) == [slice(0, 6), slice(6, 11)]
    assert both.pool_size(11) == 6 + 5 and both.batch_size == 16
    picks = pp.generate_normal(block_scene.object, mp.GripperSpec(), 11, seed=0, grasp=SHORT)
    inputs = make_inputs(block_scene, SHORT, picks)
    out, traces = both.run(inputs)
    assert traces is None
    np.testing.assert_array_equal(out["x"], inputs.qpos0[:, 0])
    np.testing.assert_array_equal(out["device"], [0] * 6 + [1] * 5)
    np.testing.assert_array_equal(both.last_diagnostics.overflow, [0] * 6 + [1] * 5)
    assert both.pool_stats.picks == 11 and both.stats.n == 11
    assert both.stats.compile_s == 1.0  # side by side: the longest, not the sum


# --------------------------------------------------------------------------- warp
@pytest.mark.mjx
@pytest.mark.skipif(
    os.environ.get(devices.ALLOW_CPU_ENV) != "1" or importlib.util.find_spec("warp") is None,
    reason="Warp on the CPU: needs warp-lang and MJX_PICK_WARP_CPU=1 (minutes)",
)
def test_warp_on_cpu_agrees_with_c_and_grows_overflowing_buffers(
    door_opener, fresh_probe, monkeypatch
):
    gripper = mp.load_gripper("robotiq-2f85")
    scene = mp.build_scene(door_opener, gripper, grasp=SHORT)
    picks = pp.generate_normal(door_opener, gripper, 6, seed=3, grasp=SHORT)
    inputs = make_inputs(scene, SHORT, picks)
    c, _ = make_backend("mujoco", scene, SHORT, batch_size=6).run(inputs)
    warp = make_backend("mjx-warp", scene, SHORT, batch_size=4, ticks_per_call=20)
    w, _ = warp.run(inputs)
    assert warp.name == "mjx-warp" and warp.growths == 0
    assert (warp.last_diagnostics.overflow == 0).all()
    assert (warp.last_diagnostics.nefc_max <= warp.buffers.rows).all()
    assert np.mean(w["success"] == c["success"]) >= 0.8
    # buffers too small: detected, grown, re-simulated -- the same labels
    small = make_backend(
        "mjx-warp", scene, SHORT, batch_size=4, ticks_per_call=20, buffers=bw.BufferSizes(4, 24)
    )
    t, _ = small.run(inputs)
    assert small.growths >= 1 and (small.last_diagnostics.overflow == 0).all()
    np.testing.assert_array_equal(t["success"], w["success"])
    # and when growing is not allowed, a clear error instead of a result
    monkeypatch.setattr(warp_buffers, "MAX_GROWTH", 0)
    tiny = make_backend(
        "mjx-warp", scene, SHORT, batch_size=4, ticks_per_call=20, buffers=bw.BufferSizes(1, 8)
    )
    with pytest.raises(bw.BufferOverflowError, match="NEFC"):
        tiny.run(inputs.take(slice(0, 2)))
