"""MJX backends: every pick-point of a batch in one jitted JAX program, MJX's JAX physics
(backend 'mjx', the differentiable physics only) or MuJoCo Warp through MJX (the
'mjx-warp' subclass). Details: docs/engine.md (engine/mjx_backend.py).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import os
import threading
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from mjx_pick.core import cache
from mjx_pick.core.config import ConfigError
from mjx_pick.core.physics import differentiable_mismatches, differentiable_physics
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine.backend import PickInputs, RunStats, addresses
from mjx_pick.engine.pool import (
    DEFAULT_SHRINK_LEVELS,
    SHRINK_MIN_SLOTS,
    Diagnostics,
    PoolStats,
    shrink_sizes,
)
from mjx_pick.kernels import grasp as gk

# TF32 matrix products would change contact solutions on GPUs: the rollouts are traced
# with full-precision products, without changing the process-wide default (a user's own
# JAX code keeps its setting)
MATMUL_PRECISION = os.environ.get("MJX_PICK_MATMUL", "highest")


def _import_mjx():
    """``mujoco.mjx``, imported without the lines it prints when warp-lang does not load
    ("Failed to import warp: ..."): MJX's JAX physics, what this backend runs, never
    uses Warp, and a run on it has nothing to do with them (the Warp backends say why
    they cannot run themselves, ``devices.warp_problem``). Anything else it prints is
    passed on."""
    import contextlib
    import io

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        from mujoco import mjx
    for line in printed.getvalue().splitlines():
        if not line.startswith(("Failed to import warp", "Failed to import mujoco_warp")):
            print(line)
    return mjx


mjx = _import_mjx()


def _precise(fn):
    """fn, traced with MATMUL_PRECISION for its matrix products (scoped to it alone)."""

    def traced(*args):
        with jax.default_matmul_precision(MATMUL_PRECISION):
            return fn(*args)

    return traced


# control periods per refill round of a pool: a finished slot idles up to this many
# ticks before it is refilled (0.1 s of simulated time at the 5 ms period), while the
# round's fixed work (a restart forward, merges, gathers) stays small next to its ~100
# physics steps per slot (benchmarks/throughput.py compares the choices)
DEFAULT_TICKS_PER_CALL = 20


class KeptPrograms:
    """The compiled programs of the latest backend identity
    (:meth:`MjxBackend.program_identity`), kept by the process after their backend is
    gone: a later run on the same scene and procedure -- the GUI's next job, a notebook's
    next evaluate -- starts simulating without tracing and compiling again. One identity
    only: a program holds its model and initial data on the device, so another scene's
    programs are dropped before its own compile (no more device memory than one
    backend's programs, as before). Keys: the devices and the program's kind and input
    shapes (several GPUs run one backend each, of one identity)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._identity = None
        self._programs: dict = {}

    def get(self, identity: tuple, key: tuple):
        """The program kept for key under identity, or None; another identity's programs
        are dropped."""
        with self._lock:
            if self._identity != identity:
                self._programs.clear()
                self._identity = identity
            return self._programs.get(key)

    def put(self, identity: tuple, key: tuple, program) -> None:
        """Keep program, unless another identity took over while it compiled."""
        with self._lock:
            if self._identity == identity:
                self._programs[key] = program

    def clear(self) -> None:
        """Drop every kept program (the next backend compiles its own)."""
        with self._lock:
            self._programs.clear()
            self._identity = None


KEPT_PROGRAMS = KeptPrograms()


def model_digest(model: mujoco.MjModel) -> str:
    """SHA-256 of a model's binary (every field, so a model changed after its scene was
    built is a different model)."""
    buffer = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return cache.digest(buffer)


@dataclasses.dataclass(frozen=True, eq=False)
class Physics:
    """What a rollout program closes over: the device model and initial data.

    impl: 'jax' or 'warp'. overflow(d) -> int32 bitmask of buffer overflows of one
    simulation (a warp ``OverflowType`` subset; always 0 for 'jax', whose buffers hold
    every possible contact). nefc(d) -> int32 constraint rows in use (-1 for 'jax').
    nacon(d) -> int32 contacts in use over ALL simulations of the call (-1 for 'jax').
    """

    model: mjx.Model
    data0: mjx.Data
    impl: str
    overflow: Callable = lambda d: jnp.int32(0)
    nefc: Callable = lambda d: jnp.int32(-1)
    nacon: Callable = lambda d: jnp.int32(-1)


def shipped_physics_files() -> tuple[str, str]:
    """The shipped --solver and --contact TOMLs of the differentiable physics (paths)."""
    from importlib import resources

    folder = resources.files("mjx_pick.assets")
    return tuple(str(folder / f"differentiable_{k}.toml") for k in ("solver", "contact"))


def check_physics(scene: Scene) -> None:
    """Refuse a scene MJX's JAX engine would not simulate as its settings say: it runs
    the differentiable physics alone (``physics.DIFFERENTIABLE_SOLVER``, pads without a
    contact margin). A ConfigError names every setting that differs and what to pass."""
    wrong = differentiable_mismatches(scene.solver, scene.contact.pad_margin_m * 1e3)
    if wrong:
        solver_file, contact_file = shipped_physics_files()
        raise ConfigError(
            f"{', '.join(wrong)}: MJX's JAX physics (backend 'mjx', calibration's jvp "
            f"estimator) runs the differentiable physics only ({differentiable_physics()}); "
            f"pass --solver {solver_file} and --contact {contact_file} (or pad_margin_mm = 0 "
            "in your contact file; in Python: SolverParams.differentiable(), "
            "ContactParams.differentiable()), or simulate these settings with backend "
            "'mujoco' or 'warp'"
        )


def jax_model(model: mujoco.MjModel) -> mjx.Model:
    """MJX's JAX implementation of a scene's model.

    Its collider implements no margin between a box and a mesh (``put_model`` refuses
    one): :func:`check_physics` refuses a scene with a pad margin; other margins (an
    MJCF gripper's own geoms') are left out here, as a margin of 0.
    """
    if model.pair_margin.any() or model.geom_margin.any():
        model = copy.copy(model)
        model.pair_margin[:] = 0.0
        model.geom_margin[:] = 0.0
    return mjx.put_model(model, impl="jax")


def jax_physics(scene: Scene) -> Physics:
    """MJX's JAX implementation on JAX's default device (:func:`jax_model`), for a scene
    of the differentiable physics (:func:`check_physics`)."""
    check_physics(scene)
    mx = jax_model(scene.model)
    return Physics(mx, mjx.make_data(mx), "jax")


def _physics_steps(phys: Physics, m, d, diag: Diagnostics, n_sub: int):
    """n_sub physics steps, folding each step's buffer use into diag."""

    def physics(carry, _):
        d, g = carry
        d = mjx.step(m, d)
        g = Diagnostics(
            g.overflow | phys.overflow(d),
            jnp.maximum(g.nefc_max, phys.nefc(d)),
            jnp.maximum(g.nacon_max, phys.nacon(d)),
        )
        return (d, g), None

    (d, diag), _ = jax.lax.scan(physics, (d, diag), None, length=n_sub)
    return d, diag


def _pick_model(phys: Physics, pair_friction, pair_solref, pair_solimp, model):
    """One pick's mjx.Model: the compiled one with this pick's contact-pair parameters
    and model fields (model: MjModel field name -> this pick's values, a gripper
    variant's; ``engine.variants``), each in the device model's dtype."""
    m = phys.model
    fields, options = {}, {}
    for k, v in (model or {}).items():
        if k.startswith("opt."):  # a solver option (engine.variants.OPT_FIELDS)
            options[k[4:]] = jnp.asarray(v, getattr(m.opt, k[4:]).dtype)
        else:
            # MuJoCo's layout in the device model's shape: Warp's model holds some
            # fields in its own shape (geom_aabb (ngeom, 2, 3) for MuJoCo's (ngeom, 6)),
            # filled from MuJoCo's array in row-major order
            like = getattr(m, k)
            fields[k] = jnp.reshape(jnp.asarray(v, like.dtype), like.shape)
    if options:
        m = m.replace(opt=m.opt.replace(**options))
    return m.replace(
        pair_friction=pair_friction, pair_solref=pair_solref, pair_solimp=pair_solimp, **fields
    )


def _initial(
    phys: Physics,
    ad: gk.Addresses,
    qpos0,
    params,
    pair_friction,
    pair_solref,
    pair_solimp,
    model=None,
    forward: bool = True,
):
    """One pick's model, data (after mj_forward), control state and accumulators.
    forward=False: the data before mj_forward, of the same shapes and dtypes (a shape
    of the carry, without tracing MJX's forward)."""
    m = _pick_model(phys, pair_friction, pair_solref, pair_solimp, model)
    s, a = gk.initial(ad, qpos0)
    d = phys.data0.replace(qpos=qpos0, ctrl=gk.command(ad, s, qpos0))
    if forward:
        d = mjx.forward(m, d)
    diag = Diagnostics(phys.overflow(d), phys.nefc(d), phys.nacon(d))
    return m, d, s, a, diag


def make_rollout(
    scene: Scene,
    grasp: GraspConfig,
    record: bool,
    mesh: Mesh | None = None,
    phys: Physics | None = None,
    diagnostics: bool = False,
):
    """The batched rollout: (qpos0, params, friction, solref, solimp[, model]) ->
    (results, traces), or (results, traces, Diagnostics) with diagnostics, jitted. Every
    pick runs all ``grasp.n_ticks()`` ticks; traces are None unless record. model: per-pick
    model fields (``PickInputs.model``: name -> (N, ...)), batched mjx.Model fields of
    the one program; left out, every pick runs the scene's model.

    mesh: with several devices, each runs its slice of the batch as its own program
    (``shard_map``). Left to the SPMD partitioner, the vmapped constraint solver's
    while-loop test ("is any simulation still iterating?") became an all-reduce across
    devices at every solver iteration of every physics step (seen in the compiled HLO):
    a synchronisation that cost 10-16 % of the time on 2-8 H200s.
    phys: the MJX implementation (default: the JAX one).
    """
    phys = phys or jax_physics(scene)
    ad = addresses(scene)
    n_sub = grasp.substeps(scene.solver)
    n_ticks = grasp.n_ticks()
    o = ad.object_qpos

    def rollout_one(qpos0, params, pair_friction, pair_solref, pair_solimp, model=None):
        m, d, s, a, diag = _initial(
            phys, ad, qpos0, params, pair_friction, pair_solref, pair_solimp, model
        )
        pos0, quat0 = qpos0[o : o + 3], qpos0[o + 3 : o + 7]

        def control_period(carry, _):
            d, s, a, g = carry
            s, a, ctrl, row = gk.tick(
                params, ad, s, a, d.qpos, d.qvel, d._impl.cfrc_ext, pos0, quat0
            )
            d, g = _physics_steps(phys, m, d.replace(ctrl=ctrl), g, n_sub)
            return (d, s, a, g), (row if record else None)

        (_, _, a, diag), rows = jax.lax.scan(control_period, (d, s, a, diag), None, length=n_ticks)
        if diagnostics:
            return gk.finalize(params, a), rows, diag
        return gk.finalize(params, a), rows

    return jax.jit(_precise(_shard(jax.vmap(rollout_one), mesh)))


def _shard(batched, mesh: Mesh | None):
    if mesh is None or mesh.size <= 1:
        return batched
    spec = PartitionSpec("batch")
    # check_vma off: MJX's solver mixes device-varying and uniform values in
    # lax.cond branches, which the varying-axis type check rejects
    return jax.shard_map(batched, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)


class Slot(NamedTuple):
    """One simulation slot of a refilled pool (batched along the pool axis)."""

    d: tuple  # the leaves of its mjx.Data (an mjx.Data inside a call)
    pair_friction: jax.Array  # (npair, 5)
    pair_solref: jax.Array  # (npair, 2)
    pair_solimp: jax.Array  # (npair, 5)
    model: dict  # the pick's model fields (PickInputs.model), name -> (...)
    params: gk.GraspParams
    s: gk.ControlState
    a: gk.Accumulators
    pos0: jax.Array  # (3,) m, the object's initial position
    quat0: jax.Array  # (4,) its initial orientation
    k: jax.Array  # int32, control ticks this pick has run
    diag: Diagnostics


def _slot_axes(phys: Physics):
    """vmap axes of a Slot, whose Data is carried as its tuple of leaves: 0 everywhere,
    except (Warp) the Data fields that Warp keeps once for all simulations of a call --
    the contact buffer and its counters. Mapped like the rest, the pool's carried state
    would hold a copy of the whole contact buffer per slot (slots x naconmax contacts).
    (A Data-shaped axes tree is no help: vmap cannot match a prefix tree against
    Warp's Data node.)"""
    if phys.impl != "warp":
        return 0
    from mujoco.mjx._src.types import tree_path_to_attr_str
    from mujoco.mjx.warp import types as mjxw_types

    batched = mjxw_types._BATCH_DIM["Data"]  # the rule Data.where follows
    paths = jax.tree_util.tree_flatten_with_path(phys.data0)[0]
    d_axes = tuple(0 if batched.get(tree_path_to_attr_str(p), True) else None for p, _ in paths)
    return Slot(d_axes, *([0] * (len(Slot._fields) - 1)))


def make_pool(
    scene: Scene,
    grasp: GraspConfig,
    ticks_per_call: int,
    slots: int,
    mesh: Mesh | None = None,
    physics_for: Callable[[int], Physics] | None = None,
    shrink_levels: int = 0,
    shrink_min_slots: int = 1,
):
    """A refilled pool of `slots` simulations as ONE jitted program:
    (valid, qpos0, params, friction, solref, solimp, model) -> (results, ticks,
    Diagnostics, rounds); model: per-pick model fields as in make_rollout (a dict,
    possibly empty).

    The inputs hold N pick-points (valid (N,) bool: False for padding, which comes
    last). Every slot starts a pick; then, in a ``lax.while_loop`` until every pick has
    ended, all slots run ``ticks_per_call`` control periods (a round), the picks that
    ended write their results to row pick-id of the (N,) outputs, and their slots take
    the next picks in order. A slot's pick freezes once it is finished (DONE, diverged,
    or ``grasp.n_ticks()`` ticks run): its control state and accumulators no longer
    change, exactly as in ``make_rollout`` where nothing accumulates after DONE, though
    its physics keeps stepping (a vmapped program steps every slot) until it is
    refilled. ticks: (N,) int32 control periods each pick ran; rounds: (L,) int32
    rounds run at each pool size of ``shrink_sizes(slots per device, shrink_levels,
    shrink_min_slots)`` (per device).

    The tail (``shrink_levels`` > 0): once every pick has been handed out, the pool
    keeps stepping slots whose last pick has ended until the longest-running pick
    ends. When at most half of the slots are still live, the live ones are moved into
    a pool of half the size (their state gathered; for Warp, a fresh contact buffer of
    the smaller size -- contacts are found anew at every step), up to
    ``shrink_levels`` times, never below ``shrink_min_slots`` per device. A pick's
    physics and control do not depend on which slot or pool size runs it, so the results
    are those of a run without shrinking.

    physics_for(n_worlds) -> Physics: the device model and initial data for a pool of
    n_worlds simulations per device (Warp sizes its contact buffer by it; default: MJX's
    JAX physics).
    """
    physics_for = physics_for or (lambda n_worlds: jax_physics(scene))
    n_dev = mesh.size if mesh is not None and mesh.size > 1 else 1
    sizes = shrink_sizes(slots // n_dev, shrink_levels, shrink_min_slots)
    ad = addresses(scene)
    n_sub, n_ticks = grasp.substeps(scene.solver), grasp.n_ticks()
    # one physics (Warp: a contact buffer sized for it) and one set of programs per size
    physes = [physics_for(size) for size in sizes]
    levels = [_pool_programs(p, ad, n_sub, n_ticks, ticks_per_call) for p in physes]

    def run_queue(valid, *inputs):
        return _run_queue(sizes, physes, levels, valid, *inputs)

    return jax.jit(_precise(_shard(run_queue, mesh)))


def _finished(slot: Slot, n_ticks: int):
    """Whether each slot's pick has ended: DONE, diverged, or n_ticks control periods run."""
    return (slot.s.phase == gk.DONE) | slot.a.diverged | (slot.k >= n_ticks)


def _pool_programs(phys: Physics, ad, n_sub: int, n_ticks: int, ticks_per_call: int):
    """(batched start, batched advance, Slot axes, batched shapes) of a pool run with
    phys (Warp's Data tree holds its contact buffer's size: one set per pool size).
    advance runs ticks_per_call control periods of n_sub physics steps on every slot,
    the slots marked fresh first restarted on their new pick's inputs. shapes: the
    (Slot, results) that start and advance return, for ``jax.eval_shape``: start without
    MJX's forward (whose Data has the shapes and dtypes of the one it is given; the
    loops' carries would refuse any other), so that finding the carry's shapes does not
    trace MJX (seconds per trace on a CPU)."""
    axes = _slot_axes(phys)
    d_tree = jax.tree.structure(phys.data0)
    o = ad.object_qpos

    def start(qpos0, params, pair_friction, pair_solref, pair_solimp, model, forward=True):
        _, d, s, a, diag = _initial(
            phys, ad, qpos0, params, pair_friction, pair_solref, pair_solimp, model, forward
        )
        pos0, quat0 = qpos0[o : o + 3], qpos0[o + 3 : o + 7]
        args = (pair_friction, pair_solref, pair_solimp, model, params, s, a, pos0, quat0)
        return Slot(tuple(d_tree.flatten_up_to(d)), *args, jnp.int32(0), diag)

    def shapes_one(*inputs):
        slot = start(*inputs, forward=False)
        return slot, gk.finalize(slot.params, slot.a)

    def advance_one(slot: Slot, fresh, *inputs):
        new = start(*inputs)
        # Data goes through Data.where: Warp's shared contact buffer is kept, not merged
        d = d_tree.unflatten(slot.d).where(fresh, d_tree.unflatten(new.d))
        rest = jax.tree.map(
            lambda n, c: jnp.where(fresh, n, c), new._replace(d=None), slot._replace(d=None)
        )
        slot = rest._replace(d=d)
        m = _pick_model(phys, slot.pair_friction, slot.pair_solref, slot.pair_solimp, slot.model)

        def control_period(slot: Slot, _):
            s, a, ctrl, _ = gk.tick(
                slot.params,
                ad,
                slot.s,
                slot.a,
                slot.d.qpos,
                slot.d.qvel,
                slot.d._impl.cfrc_ext,
                slot.pos0,
                slot.quat0,
            )
            # a finished pick's control state, metrics and buffer counts stay as they are
            frozen = _finished(slot, n_ticks)
            keep = lambda old, new: jax.tree.map(lambda x, y: jnp.where(frozen, x, y), old, new)
            ctrl = jnp.where(frozen, slot.d.ctrl, ctrl)
            d, diag = _physics_steps(phys, m, slot.d.replace(ctrl=ctrl), slot.diag, n_sub)
            k = slot.k + jnp.where(frozen, 0, 1).astype(jnp.int32)
            slot = slot._replace(
                d=d, s=keep(slot.s, s), a=keep(slot.a, a), k=k, diag=keep(slot.diag, diag)
            )
            return slot, None

        slot, _ = jax.lax.scan(control_period, slot, None, length=ticks_per_call)
        slot = slot._replace(d=tuple(d_tree.flatten_up_to(slot.d)))
        return slot, gk.finalize(slot.params, slot.a), _finished(slot, n_ticks), slot.k, slot.diag

    advance = jax.vmap(advance_one, in_axes=(axes,) + (0,) * 7, out_axes=(axes, 0, 0, 0, 0))
    shapes = jax.vmap(shapes_one, out_axes=(axes, 0))
    return jax.vmap(start, out_axes=axes), advance, axes, shapes


def _compact(state: Slot, order, phys: Physics, axes) -> Slot:
    """The slots at `order` (live ones first) as the pool of phys (its programs' Slot
    axes): gathered state; for Data fields kept once per call (Warp's contact buffer),
    that pool's own."""
    small = jax.tree.leaves(phys.data0)
    d_axes = axes.d if isinstance(axes, Slot) else (axes,) * len(small)
    d = tuple(
        x[order] if axis == 0 else fresh_leaf
        for x, axis, fresh_leaf in zip(state.d, d_axes, small, strict=True)
    )
    rest = jax.tree.map(lambda x: x[order], state._replace(d=None))
    return rest._replace(d=d)


def _run_queue(sizes, physes, levels, valid, *inputs):
    """The pool's queue (see make_pool): every pick of inputs (valid (N,) bool, padding
    last) through slots refilled in rounds, at each pool size of sizes in turn (physes,
    levels: their physics and programs); (results, ticks, Diagnostics, rounds)."""
    n = valid.shape[0]
    n_valid = jnp.sum(valid.astype(jnp.int32))
    size = sizes[0]
    ids = jnp.arange(size, dtype=jnp.int32)

    def gather(pick):
        i = jnp.clip(pick, 0, n - 1)
        return tuple(jax.tree.map(lambda x: x[i], inputs))

    pick0 = jnp.where(ids < n_valid, ids, -1)
    fresh0 = jnp.ones(size, bool)
    # every slot is fresh in the first round: zeros of the right shapes will do
    slot_s, out_s = jax.eval_shape(levels[0][3], *gather(pick0))
    zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), slot_s)
    ticks_s, diag_s = slot_s.k, slot_s.diag  # as advance returns them
    rows = jax.tree.map(lambda x: jnp.zeros((n,) + x.shape[1:], x.dtype), (out_s, ticks_s, diag_s))

    def body(c, advance):
        state, pick, fresh, nxt, rows, rounds = c
        state, out, finished, ticks, diag = advance(state, fresh, *gather(pick))
        ended = finished & (pick >= 0)
        at = jnp.where(ended, pick, n)  # row n is out of range: dropped
        rows = jax.tree.map(lambda r, v: r.at[at].set(v, mode="drop"), rows, (out, ticks, diag))
        # the ended slots take the next picks, in slot order
        new = nxt + jnp.cumsum(ended.astype(jnp.int32)) - 1
        ok = ended & (new < n_valid)
        pick = jnp.where(ended, jnp.where(ok, new, -1), pick)
        nxt = nxt + jnp.sum(ok.astype(jnp.int32))
        return state, pick, ok, nxt, rows, rounds + 1

    carry = (zeros, pick0, fresh0, jnp.minimum(size, n_valid), rows, jnp.int32(0))
    rounds = []
    for level, size in enumerate(sizes):
        last = level == len(sizes) - 1

        def cond(c, last=last, half=size // 2):
            live = c[1] >= 0
            # leave for the next, smaller pool once the queue is empty and at most
            # half of the slots are live
            shrink = (c[3] >= n_valid) & (jnp.sum(live.astype(jnp.int32)) <= half)
            return jnp.any(live) & (last | ~shrink)

        step = functools.partial(body, advance=levels[level][1])
        state, pick, fresh, nxt, rows, k = jax.lax.while_loop(cond, step, carry)
        rounds.append(k)
        if not last:
            # live slots first, in slot order; the rest of the smaller pool is idle
            order = jnp.argsort(pick < 0, stable=True)[: sizes[level + 1]]
            state = _compact(state, order, physes[level + 1], levels[level + 1][2])
            carry = (state, pick[order], fresh[order], nxt, rows, jnp.int32(0))
    out, ticks, diag = rows
    return out, ticks, diag, jnp.stack(rounds)


def _single(inputs: PickInputs) -> PickInputs:
    """inputs with their model fields in float32, as the device model holds them (MuJoCo's
    float64 values, rounded once on the host)."""
    if not inputs.model:
        return inputs
    return inputs.replace(model={k: np.asarray(v, np.float32) for k, v in inputs.model.items()})


def _fields_key(args) -> tuple:
    """The per-pick model fields of a call's inputs (PickInputs order), names and
    shapes: one compiled program per set."""
    return tuple((k, tuple(v.shape[1:])) for k, v in sorted(args[5].items()))


class MjxBackend:
    """Runs PickInputs in fixed-size batches (padded), one compile per batch size.

    refill: run through a pool of ``batch_size`` slots refilled as picks end (see the
    module docstring); a run of fewer picks than the pool uses a smaller pool (rounded
    up to a multiple of ``POOL_QUANTUM`` so that small runs of different sizes share
    compiles). shrink_levels: halvings of the pool in a run's tail (see make_pool).
    Traces (``record=True``) always use the full-length rollout. A new backend whose
    :meth:`program_identity` equals the last one's runs the programs the process
    compiled for it (:data:`KEPT_PROGRAMS`).
    """

    name = "mjx"
    impl = "jax"
    POOL_QUANTUM = 256
    SHRINK_MIN_SLOTS = SHRINK_MIN_SLOTS  # engine.pool's: a class attribute tests may lower

    def __init__(
        self,
        scene: Scene,
        grasp: GraspConfig,
        batch_size: int,
        devices=None,
        refill: bool = False,
        ticks_per_call: int = DEFAULT_TICKS_PER_CALL,
        shrink_levels: int = DEFAULT_SHRINK_LEVELS,
    ):
        if int(ticks_per_call) < 1:
            raise ValueError(f"ticks_per_call = {ticks_per_call} must be >= 1")
        if int(shrink_levels) < 0:
            raise ValueError(f"shrink_levels = {shrink_levels} must be >= 0")
        if self.impl == "jax":
            check_physics(scene)  # before anything is compiled or simulated
        self.scene, self.grasp = scene, grasp
        self.devices = list(devices) if devices is not None else jax.local_devices()
        n_dev = len(self.devices)
        # every device gets the same number of simulations
        self.batch_size = int(-(-int(batch_size) // n_dev) * n_dev)
        d0 = self.devices[0]
        self.device = f"{d0.platform}:{d0.device_kind}" + (f" x{n_dev}" if n_dev > 1 else "")
        self.mesh = Mesh(np.asarray(self.devices), ("batch",))
        self.sharding = NamedSharding(self.mesh, PartitionSpec("batch"))
        self.refill = bool(refill)
        self.ticks_per_call = int(ticks_per_call)
        self.shrink_levels = int(shrink_levels)
        self.stats = RunStats()
        self.pool_stats = PoolStats()
        self.last_diagnostics: Diagnostics | None = None
        self._compiled = {}  # this backend's programs, by kind and input shapes

    # --- what an implementation changes
    def physics(self, n_worlds: int) -> Physics:
        """The MJX model and data for programs of n_worlds simulations per device."""
        return jax_physics(self.scene)

    def check_diagnostics(self, diag: Diagnostics, inputs: PickInputs) -> None:
        """Called after each run with every pick's Diagnostics (numpy)."""

    def program_identity(self) -> tuple:
        """What this backend's compiled programs depend on besides their inputs' shapes
        and the devices: the implementation, the model, the procedure and the pool's
        settings (a subclass adds its own)."""
        return (
            type(self).__qualname__,
            self.impl,
            model_digest(self.scene.model),
            repr(self.grasp),
            self.ticks_per_call,
            self.shrink_levels,
            self.SHRINK_MIN_SLOTS,
        )

    def _program(self, key: tuple, build: Callable[[], Callable]) -> Callable:
        """The compiled program for key (its kind and input shapes): this backend's own,
        else the process's for the same identity, else built now (compile time)."""
        fn = self._compiled.get(key)
        if fn is not None:
            return fn
        identity = self.program_identity()
        on_devices = (tuple((d.platform, d.id) for d in self.devices), *key)
        fn = KEPT_PROGRAMS.get(identity, on_devices)
        if fn is None:
            t0 = time.perf_counter()
            fn = build()
            self.stats.compile_s += time.perf_counter() - t0
            KEPT_PROGRAMS.put(identity, on_devices, fn)
        self._compiled[key] = fn
        return fn

    # --- full-length batches
    def _compiled_for(self, args, record: bool):
        def build():
            per_device = len(args[0]) // len(self.devices)
            phys = self.physics(per_device)
            fn = make_rollout(self.scene, self.grasp, record, self.mesh, phys, diagnostics=True)
            return fn.lower(*args).compile()

        return self._program(("rollout", len(args[0]), record, _fields_key(args)), build)

    def device_bytes_per_pick(self) -> int:
        """Rough device memory of one simulation: 4x its mjx.Data (measured peak on an H100
        at batch 16384: 1.5x; at 4096: 3x -- fixed overheads)."""
        d = self.physics(1).data0
        return 4 * sum(int(x.nbytes) for x in jax.tree.leaves(d) if hasattr(x, "nbytes"))

    def run(self, inputs: PickInputs, record: bool = False):
        """Simulate all inputs; returns (results dict of (N,) arrays, traces (N, T, F) or None)."""
        if self.refill and not record and len(inputs):
            merged, diag = self._run_pool(inputs)
            traces = None
        else:
            merged, traces, diag = self._run_batches(inputs, record)
        self.last_diagnostics = diag
        self.check_diagnostics(diag, inputs)
        self.stats.n += len(inputs)
        return merged, traces

    def _run_batches(self, inputs: PickInputs, record: bool):
        inputs = _single(inputs)
        n = len(inputs)
        n_dev = len(self.devices)
        size = self.batch_size
        if record:  # a few re-simulated pick-points: a small batch
            size = min(size, -(-max(n, 1) // n_dev) * n_dev)
        results, traces, diags = [], [], []
        for start in range(0, n, size):
            chunk = inputs.take(slice(start, start + size))
            m = len(chunk)
            args = tuple(jax.device_put(a, self.sharding) for a in chunk.pad_to(size))
            fn = self._compiled_for(args, record)
            t0 = time.perf_counter()
            out, rows, diag = jax.block_until_ready(fn(*args))
            self.stats.run_s += time.perf_counter() - t0
            results.append({k: np.asarray(v)[:m] for k, v in out.items()})
            diags.append(jax.tree.map(lambda x, m=m: np.asarray(x)[:m], diag))
            if record:
                traces.append(np.asarray(rows)[:m])
        merged = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
        diag = jax.tree.map(lambda *x: np.concatenate(x), *diags)
        return merged, (np.concatenate(traces) if record else None), diag

    # --- refilled pool
    def pool_size(self, n: int) -> int:
        """Slots for a run of n picks: the batch size, or fewer for a small run."""
        n_dev = len(self.devices)
        q = self.POOL_QUANTUM * n_dev
        return min(self.batch_size, -(-n // q) * q)

    def _pool_fn(self, size: int, args):
        """The compiled pool program for `size` slots and these inputs' shapes."""

        def build():
            fn = make_pool(
                self.scene,
                self.grasp,
                self.ticks_per_call,
                size,
                self.mesh,
                self.physics,
                self.shrink_levels,
                self.SHRINK_MIN_SLOTS,
            )
            return fn.lower(*args).compile()

        return self._program(("pool", size, len(args[0]), _fields_key(args[1:])), build)

    def _run_pool(self, inputs: PickInputs):
        """Every pick through a pool of slots refilled as picks end, in one device call;
        (results, Diagnostics) in pick-point order."""
        inputs = _single(inputs)
        n = len(inputs)
        size = self.pool_size(n)
        # the queue is padded to a whole number of pools: runs of similar size (the
        # chunks of a long evaluation) share one compiled program
        n_pad = -(-n // size) * size
        put = lambda a: jax.device_put(a, self.sharding)
        args = (put(np.arange(n_pad) < n),) + tuple(put(a) for a in inputs.pad_to(n_pad))
        fn = self._pool_fn(size, args)
        t0 = time.perf_counter()
        out, ticks, diag, rounds = jax.block_until_ready(fn(*args))
        self.stats.run_s += time.perf_counter() - t0
        n_dev = len(self.devices)
        sizes = np.asarray(shrink_sizes(size // n_dev, self.shrink_levels, self.SHRINK_MIN_SLOTS))
        rounds = np.asarray(rounds, np.int64).reshape(n_dev, len(sizes))
        ticks = np.asarray(ticks)[:n]
        slot_ticks = int((rounds * sizes).sum()) * self.ticks_per_call
        self.pool_stats.add(int(rounds.sum()), slot_ticks, int(ticks.sum()), n)
        results = {k: np.array(v)[:n] for k, v in out.items()}
        return results, Diagnostics(*(np.array(x)[:n] for x in diag))
