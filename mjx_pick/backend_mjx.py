"""MJX backend: every pick-point of a batch in ONE jitted computation (GPU, or CPU).

``rollout_one`` simulates one pick-point: ``lax.scan`` over control periods, each
running the shared tick (measure, P controller, phase machine, metrics) and
``n_substeps`` MJX physics steps. The batch is ``vmap`` of it, jitted once per batch
shape; per-pick contact-pair parameters enter as traced model fields, so sweeps and
gradients need no new code.

With several local devices the batch axis is sharded over all of them (a one-axis
``Mesh``, ``NamedSharding`` for the data and ``shard_map`` for the program):
pick-points are independent, so each device simulates its slice and nothing is
communicated. Multi-host runs start with
``jax.distributed.initialize()``; ``mjx_pick.evaluate`` then gives each process every
P-th chunk.

Only per-pick summaries leave the device; full traces are produced only when asked
(``record=True``), for the few pick-points whose plots are wanted (they are
re-simulated: a trace of every pick of a large batch would not fit in memory).
"""

from __future__ import annotations

import os
import time

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from mujoco import mjx

from mjx_pick.grasp import GraspConfig
from mjx_pick.kernels import grasp as gk
from mjx_pick.scene import Scene
from mjx_pick.simulate import PickInputs, RunStats, addresses

# TF32 matrix products would change contact solutions on GPUs
jax.config.update("jax_default_matmul_precision", os.environ.get("MJX_PICK_MATMUL", "highest"))


def make_rollout(scene: Scene, grasp: GraspConfig, record: bool, mesh: Mesh | None = None):
    """The batched rollout: (qpos0, params, friction, solref, solimp) -> results, jitted.

    mesh: with several devices, each runs its slice of the batch as its own program
    (``shard_map``). Left to the SPMD partitioner, the vmapped constraint solver's
    while-loop test ("is any simulation still iterating?") became an all-reduce across
    devices at every solver iteration of every physics step (seen in the compiled HLO):
    a synchronisation that cost 10-16 % of the time on 2-8 H200s.
    """
    mx = mjx.put_model(scene.model)
    d0 = mjx.make_data(mx)
    ad = addresses(scene)
    n_sub = grasp.substeps(scene.solver)
    n_ticks = grasp.n_ticks()
    o = ad.object_qpos

    def rollout_one(qpos0, params, pair_friction, pair_solref, pair_solimp):
        m = mx.replace(
            pair_friction=pair_friction, pair_solref=pair_solref, pair_solimp=pair_solimp
        )
        travel0 = qpos0[ad.finger_left_qpos]
        s = gk.initial_state(travel0)
        a = gk.initial_accumulators(travel0)
        d = d0.replace(qpos=qpos0, ctrl=gk.command(ad, s, qpos0))
        d = mjx.forward(m, d)
        pos0, quat0 = qpos0[o : o + 3], qpos0[o + 3 : o + 7]

        def physics(d, _):
            return mjx.step(m, d), None

        def control_period(carry, _):
            d, s, a = carry
            s, a, ctrl, row = gk.tick(
                params, ad, s, a, d.qpos, d.qvel, d._impl.cfrc_ext, pos0, quat0
            )
            d, _ = jax.lax.scan(physics, d.replace(ctrl=ctrl), None, length=n_sub)
            return (d, s, a), (row if record else None)

        (_, _, a), rows = jax.lax.scan(control_period, (d, s, a), None, length=n_ticks)
        return gk.finalize(params, a), rows

    batched = jax.vmap(rollout_one)
    if mesh is not None and mesh.size > 1:
        spec = PartitionSpec("batch")
        # check_vma off: MJX's solver mixes device-varying and uniform values in
        # lax.cond branches, which the varying-axis type check rejects
        batched = jax.shard_map(batched, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)
    return jax.jit(batched)


class MjxBackend:
    """Runs PickInputs in fixed-size batches (padded), one compile per batch size."""

    name = "mjx"

    def __init__(self, scene: Scene, grasp: GraspConfig, batch_size: int, devices=None):
        self.scene, self.grasp = scene, grasp
        self.devices = list(devices) if devices is not None else jax.local_devices()
        n_dev = len(self.devices)
        # every device gets the same number of simulations
        self.batch_size = int(-(-int(batch_size) // n_dev) * n_dev)
        d0 = self.devices[0]
        self.device = f"{d0.platform}:{d0.device_kind}" + (f" x{n_dev}" if n_dev > 1 else "")
        self.mesh = Mesh(np.asarray(self.devices), ("batch",))
        self.sharding = NamedSharding(self.mesh, PartitionSpec("batch"))
        self.stats = RunStats()
        self._fns = {}
        self._compiled = {}

    def _compiled_for(self, args, record: bool):
        key = (len(args[0]), record)
        if key not in self._compiled:
            if record not in self._fns:
                self._fns[record] = make_rollout(self.scene, self.grasp, record, self.mesh)
            t0 = time.perf_counter()
            self._compiled[key] = self._fns[record].lower(*args).compile()
            self.stats.compile_s += time.perf_counter() - t0
        return self._compiled[key]

    def device_bytes_per_pick(self) -> int:
        """Rough device memory of one simulation: 4x its mjx.Data (measured peak on an H100
        at batch 16384: 1.5x; at 4096: 3x -- fixed overheads)."""
        d = mjx.make_data(mjx.put_model(self.scene.model))
        return 4 * sum(int(x.nbytes) for x in jax.tree.leaves(d) if hasattr(x, "nbytes"))

    def run(self, inputs: PickInputs, record: bool = False):
        """Simulate all inputs; returns (results dict of (N,) arrays, traces (N, T, F) or None)."""
        n = len(inputs)
        n_dev = len(self.devices)
        size = self.batch_size
        if record:  # a few re-simulated pick-points: a small batch
            size = min(size, -(-max(n, 1) // n_dev) * n_dev)
        results, traces = [], []
        for start in range(0, n, size):
            chunk = inputs.take(slice(start, start + size))
            m = len(chunk)
            args = tuple(jax.device_put(a, self.sharding) for a in chunk.pad_to(size))
            fn = self._compiled_for(args, record)
            t0 = time.perf_counter()
            out, rows = jax.block_until_ready(fn(*args))
            self.stats.run_s += time.perf_counter() - t0
            results.append({k: np.asarray(v)[:m] for k, v in out.items()})
            if record:
                traces.append(np.asarray(rows)[:m])
        self.stats.n += n
        merged = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
        return merged, (np.concatenate(traces) if record else None)
