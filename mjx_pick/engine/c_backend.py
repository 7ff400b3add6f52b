"""MuJoCo C backend: the same pick-points on ``mujoco.batch`` (CPU threads).

Details: docs/engine.md (engine/c_backend.py).
"""

from __future__ import annotations

import copy
import functools
import os
import time

import jax
import mujoco
import mujoco.batch
import numpy as np

from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import devices
from mjx_pick.engine.backend import PickInputs, RunStats, addresses
from mjx_pick.engine.variants import model_value
from mjx_pick.kernels import grasp as gk


@functools.cache
def _tick_fn(ad: gk.Addresses):
    vtick = jax.vmap(gk.tick, in_axes=(0, None, 0, 0, 0, 0, 0, 0, 0))
    return jax.jit(
        lambda p, s, a, qpos, qvel, cfrc, pos0, quat0: vtick(
            p, ad, s, a, qpos, qvel, cfrc, pos0, quat0
        )
    )


@functools.cache
def _start_fn(ad: gk.Addresses):
    """The controller's state, accumulators and first command for every row, jitted: run
    eagerly, its few dozen operations would each compile a program of their own."""

    def start(qpos0):
        s, a = gk.initial(ad, qpos0)
        return s, a, gk.command(ad, s, qpos0)

    return jax.jit(jax.vmap(start))


@functools.cache
def _finalize_fn():
    return jax.jit(jax.vmap(gk.finalize))


def tick_rows(n: int) -> int:
    """Rows the jitted tick runs for a chunk of n simulations: the next power of two (at
    least 8). XLA compiles the tick once per shape (3-5 s on a 2-core CPU); studies and
    calibration call with many chunk sizes, and a few shapes serve them all. The extra
    rows repeat the last simulation's state and are dropped."""
    return max(8, 1 << (int(n) - 1).bit_length())


def _pad(x, rows: int):
    """x (n, ...) padded to (rows, ...) by repeating its last row (finite values)."""
    x = np.asarray(x)
    if len(x) == rows:
        return x
    return np.concatenate([x, np.repeat(x[-1:], rows - len(x), axis=0)])


class MujocoBackend:
    """Runs PickInputs on mujoco.batch.Batch in chunks of batch_size simulations."""

    name = "mujoco"

    def __init__(
        self, scene: Scene, grasp: GraspConfig, batch_size: int, nthread: int | None = None
    ):
        self.scene, self.grasp = scene, grasp
        self.batch_size = int(batch_size)
        self.nthread = int(nthread or os.cpu_count() or 1)
        self.device = f"cpu:{self.nthread} threads"
        self.stats = RunStats()
        self.ad = addresses(scene)
        self._cpu = devices.jax_cpu_device()
        self._batches: dict[int, mujoco.batch.Batch] = {}
        self._expanded: dict[int, set[str]] = {}  # id(batch) -> model fields it expanded

    def _batch(self, n: int) -> mujoco.batch.Batch:
        if n not in self._batches:
            model = copy.copy(self.scene.model)
            model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
            self._batches[n] = mujoco.batch.Batch(model, nsim=n, nthread=self.nthread)
        return self._batches[n]

    def _set_model_fields(self, b: mujoco.batch.Batch, fields: dict) -> None:
        """Each simulation's model fields (a gripper variant's: ``engine.variants``):
        fields maps an MjModel field to (n, *shape) values. A field a batch expanded for
        an earlier chunk and this one does not carry goes back to the scene's values."""
        done = self._expanded.setdefault(id(b), set())
        for name in done - set(fields):
            b.expand(name)[:] = model_value(self.scene.model, name)
        for name, values in fields.items():
            b.expand(name)[:] = values
            done.add(name)

    def run(self, inputs: PickInputs, record: bool = False):
        """Simulate all inputs; returns (results dict of (N,) arrays, traces (N, T, F) or None)."""
        results, traces = [], []
        for start in range(0, len(inputs), self.batch_size):
            chunk = inputs.take(slice(start, start + self.batch_size))
            with jax.default_device(self._cpu):
                out, rows = self._run_chunk(chunk, record)
            results.append(out)
            if record:
                traces.append(rows)
        self.stats.n += len(inputs)
        merged = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
        return merged, (np.concatenate(traces) if record else None)

    def _run_chunk(self, inputs: PickInputs, record: bool):
        """One batch of N <= batch_size simulations: (results of (N,) arrays, traces
        (N, T, F) or None). The controller runs jitted on >= N rows (tick_rows), the
        physics on the N alone, only the rows still running stepping each tick."""
        n = len(inputs)
        ad = self.ad
        n_sub = self.grasp.substeps(self.scene.solver)
        n_ticks = self.grasp.n_ticks()
        t_compile = time.perf_counter()
        b = self._loaded_batch(inputs)
        qpos, qvel, ctrl = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl")
        cfrc, sim_time = b.bind("cfrc_ext"), b.bind("time")
        qpos[:] = inputs.qpos0
        qvel[:] = 0.0
        # the controller runs on `rows` >= n rows (tick_rows); physics on the n alone
        rows_n = tick_rows(n)
        qpos0 = _pad(inputs.qpos0, rows_n)
        params = jax.tree.map(lambda x: _pad(x, rows_n), inputs.params)
        o = ad.object_qpos
        pos0, quat0 = qpos0[:, o : o + 3], qpos0[:, o + 3 : o + 7]
        s, a, u0 = _start_fn(ad)(qpos0)
        ctrl[:] = np.asarray(u0)[:n]
        b.forward()
        tick = _tick_fn(ad)

        def state():
            return _pad(qpos, rows_n), _pad(qvel, rows_n), _pad(cfrc, rows_n)

        tick.lower(params, s, a, *state(), pos0, quat0).compile()
        self.stats.compile_s += time.perf_counter() - t_compile

        t_run = time.perf_counter()
        broken = np.zeros(n, bool)
        rows = []
        dt = n_sub * self.scene.model.opt.timestep
        for k in range(n_ticks):
            s, a, u, row = tick(params, s, a, *state(), pos0, quat0)
            if record:
                rows.append(np.asarray(row)[:n])
            running = (np.asarray(s.phase)[:n] != gk.DONE) & ~np.asarray(a.diverged)[:n]
            if not running.any():
                break
            ctrl[:] = np.asarray(u)[:n]
            failed = _step_running(b, np.flatnonzero(running), n_sub, sim_time, (k + 1, dt))
            if failed.any():
                broken |= failed
                qpos[failed] = np.nan  # the next tick flags them diverged
        if broken.any():
            s, a, _, _ = tick(params, s, a, *state(), pos0, quat0)
        out = {k: np.asarray(v)[:n] for k, v in _finalize_fn()(params, a).items()}
        self.stats.run_s += time.perf_counter() - t_run
        return out, (_held_traces(rows, n_ticks, dt) if record else None)

    def _loaded_batch(self, inputs: PickInputs) -> mujoco.batch.Batch:
        """The batch for len(inputs) simulations, reset, with each simulation's contact
        pair values and model fields set."""
        b = self._batch(len(inputs))
        b.reset(stage=mujoco.mjtStage.mjSTAGE_NONE.value)
        b.expand("pair_friction")[:] = inputs.pair_friction
        b.expand("pair_solref")[:] = inputs.pair_solref
        b.expand("pair_solimp")[:] = inputs.pair_solimp
        self._set_model_fields(b, inputs.model)
        return b


def _step_running(b: mujoco.batch.Batch, ids, n_sub: int, sim_time, tick) -> np.ndarray:
    """Step the simulations ids of b by n_sub physics steps; (N,) bool: those that blew
    up (a SimulationError, or a time behind tick = (ticks done, control period s))."""
    k_done, dt = tick
    failed = np.zeros(len(sim_time), bool)
    try:
        b.step(ids=ids, nstep=n_sub)
    except mujoco.batch.SimulationError as err:
        failed[err.ids] = True
    # a MuJoCo auto-reset (bad accelerations) sends time back: a blow-up
    failed[ids] |= sim_time[ids] < k_done * dt - 0.5 * dt
    return failed


def _held_traces(rows: list[np.ndarray], n_ticks: int, dt: float) -> np.ndarray:
    """The recorded (N, F) rows stacked to (N, n_ticks, F): where every simulation ended
    early, the last row held (its time, column 0, going on by dt s per tick)."""
    traces = np.stack(rows, axis=1)
    if traces.shape[1] < n_ticks:  # all finished early: hold the last row
        pad = np.repeat(traces[:, -1:], n_ticks - traces.shape[1], axis=1)
        pad[..., 0] = traces[:, -1:, 0] + dt * np.arange(1, n_ticks - traces.shape[1] + 1)
        traces = np.concatenate([traces, pad], axis=1)
    return traces
