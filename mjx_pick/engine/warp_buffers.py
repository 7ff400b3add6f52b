"""Warp's preallocated buffers: contacts and constraint rows per simulation, sized by
measurement on the MuJoCo C engine (shared by both MuJoCo Warp backends).

Warp allocates contacts and constraint rows up front: ``naconmax`` contacts for ALL
simulations of a call together, ``njmax`` constraint rows for EACH. :func:`size_buffers`
sizes them from the scene: a sample of pick-points simulated on the MuJoCo C engine, the
largest counts seen, plus a margin. Warp raises an overflow bit in a simulation whose
contacts or rows did not fit (and drops them); the backends re-simulate such picks with
doubled buffers, so no result ever comes from a dropped contact.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math

import mujoco
import mujoco.batch
import numpy as np

from mjx_pick.core import cache
from mjx_pick.core.config import ConfigError, to_dict
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene

# a run whose buffers overflowed is re-simulated with doubled buffers this many times
MAX_GROWTH = 3
# buffer margin over the largest counts measured on the sample (see buffer_margin)
CONTACT_MARGIN = 1.5
CONTACT_SLACK = 4
# rows x2: Warp's convex collider makes more constraint rows per world than the C
# engine's sample shows (condim-4 pads), so rows get a wider margin than contacts
ROW_MARGIN = 2.0
ROW_SLACK = 16

log = logging.getLogger(__name__)


class BufferOverflowError(RuntimeError):
    """Warp's contact or constraint buffers overflowed even after growing them."""


@dataclasses.dataclass(frozen=True)
class BufferSizes:
    """Warp's preallocated buffers, per simulation.

    contacts: contacts per simulation; a call of n simulations gets ``naconmax =
    contacts * n`` (Warp's contact buffer is shared by all simulations of a call, so a
    simulation may use more than its share while others use less). rows: constraint
    rows per simulation (``njmax``; a hard limit for each simulation). measured_*: the
    largest counts seen when sizing (None: sizes given by hand).
    """

    contacts: int
    rows: int
    measured_contacts: int | None = None
    measured_rows: int | None = None
    sample: int = 0

    def __post_init__(self):
        for name in ("contacts", "rows"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or v < 1:
                raise ConfigError(f"buffers.{name} = {v!r} must be an integer >= 1")

    def naconmax(self, n_worlds: int) -> int:
        return int(self.contacts) * int(n_worlds)

    def grown(self, contacts: bool, rows: bool) -> BufferSizes:
        """Doubled where an overflow was seen."""
        return dataclasses.replace(
            self,
            contacts=self.contacts * (2 if contacts else 1),
            rows=self.rows * (2 if rows else 1),
        )


def buffer_margin(measured_contacts: int, measured_rows: int) -> tuple[int, int]:
    """Buffer sizes from the largest measured counts: contacts x1.5 + 4, rows x2 + 16,
    rounded up to a multiple of 4 (contacts) and 8 (rows).

    Why a margin: the sample does not hold every pick-point, per-pick contact settings
    (a friction sweep) move contacts a little, and Warp's collision functions need not
    return as many contacts per geom pair as MuJoCo C's (box-box, convex-convex with
    multi-contact): Warp makes more constraint rows per world than C's sample shows
    (contacts are pooled over all worlds, so their margin matters less). Too large
    costs time (Warp launches some kernels over every row); too small costs a re-run,
    never a wrong result (overflow is detected).
    """

    def up(x: float, q: int) -> int:
        return int(math.ceil(x / q) * q)

    contacts = up(CONTACT_MARGIN * measured_contacts + CONTACT_SLACK, 4)
    rows = up(ROW_MARGIN * measured_rows + ROW_SLACK, 8)
    return max(contacts, 4), max(rows, 8)


class _CountingBatch:
    """A mujoco.batch.Batch that records, per simulation, the most contacts (ncon) and
    constraint rows (nefc) of any physics step. Steps one substep at a time, since a
    batch reports derived fields of the last substep of a call only."""

    def __init__(self, batch: mujoco.batch.Batch):
        self._b = batch
        self._ncon = batch.bind("ncon")
        self._nefc = batch.bind("nefc")
        self.max_ncon = np.zeros(batch.nsim, np.int64)
        self.max_nefc = np.zeros(batch.nsim, np.int64)

    def __getattr__(self, name):
        return getattr(self._b, name)

    def step(self, ids=None, nstep: int = 1, stage: int = 0) -> None:
        ids = np.arange(self._b.nsim) if ids is None else np.asarray(ids)
        failed: list[np.ndarray] = []
        for _ in range(nstep):
            if not len(ids):
                break
            try:
                self._b.step(ids=ids, nstep=1, stage=stage)
            except mujoco.batch.SimulationError as err:
                # as one call of nstep substeps would: the failed ones stop, the rest go on
                failed.append(np.asarray(err.ids))
                ids = np.setdiff1d(ids, err.ids)
            np.maximum.at(self.max_ncon, ids, self._ncon[ids])
            np.maximum.at(self.max_nefc, ids, self._nefc[ids])
        if failed:
            bad = np.unique(np.concatenate(failed))
            raise mujoco.batch.SimulationError(bad, "error while sizing buffers")


def _sizing_backend(scene: Scene, grasp: GraspConfig, n: int, nthread: int | None):
    """The C backend (same controller, same procedure) with counting batches."""
    from mjx_pick.engine.c_backend import MujocoBackend

    class SizingBackend(MujocoBackend):
        def _batch(self, n: int):
            if n not in self._batches:
                model = copy.copy(self.scene.model)
                model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
                b = mujoco.batch.Batch(model, nsim=n, nthread=self.nthread)
                self._batches[n] = _CountingBatch(b)
            return self._batches[n]

    return SizingBackend(scene, grasp, n, nthread=nthread)


def measure_buffers(
    scene: Scene, grasp: GraspConfig, inputs, nthread: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate inputs on the MuJoCo C engine (the project's procedure, to the end of
    each pick) and return, per pick, the most contacts and constraint rows of any
    physics step: (ncon (N,), nefc (N,)), ints."""
    backend = _sizing_backend(scene, grasp, max(len(inputs), 1), nthread)
    backend.run(inputs)
    (counting,) = backend._batches.values()
    return counting.max_ncon[: len(inputs)].copy(), counting.max_nefc[: len(inputs)].copy()


def size_buffers(
    scene: Scene,
    grasp: GraspConfig,
    inputs=None,
    n_sample: int = 32,
    seed: int = 0,
    nthread: int | None = None,
) -> BufferSizes:
    """Warp buffer sizes for a scene, by measurement on the MuJoCo C engine (CPU).

    inputs: pick-points to measure (default: n_sample feasible pick-points of the
    scene's object and gripper, generated with seed, at the scene's contact settings).
    Returns the largest per-step counts seen with :func:`buffer_margin`'s margin. Costs
    about n_sample full picks on the CPU (seconds); the default sample's counts are a
    pure function of the model, the procedure and the sample, so they are kept in the
    cache (``mjx_pick.core.cache``) and a later run of the same scene reads them back.
    """
    if inputs is None:
        if n_sample < 1:
            raise ConfigError(f"n_sample = {n_sample} must be >= 1")
        key = {
            "scene_sha256": cache.digest(scene.portable_xml()),
            "silhouette_sha256": cache.digest(scene.object.polygon.wkb),
            "grasp": to_dict(grasp),
            "n_sample": int(n_sample),
            "seed": int(seed),
            "mujoco": mujoco.__version__,
        }

        def measure() -> dict:
            log.info("sizing Warp's buffers on %d pick-points on the C engine ...", n_sample)
            sample = _sample_inputs(scene, grasp, n_sample, seed)
            ncon, nefc = measure_buffers(scene, grasp, sample, nthread=nthread)
            return {"contacts": ncon.max(), "rows": nefc.max(), "sample": len(sample)}

        counts = cache.memo("warp_buffers", key, measure)
        mc, mr, n = (int(counts[k]) for k in ("contacts", "rows", "sample"))
    else:
        ncon, nefc = measure_buffers(scene, grasp, inputs, nthread=nthread)
        mc, mr, n = int(ncon.max()), int(nefc.max()), len(inputs)
    contacts, rows = buffer_margin(mc, mr)
    return BufferSizes(contacts, rows, mc, mr, n)


def _sample_inputs(scene: Scene, grasp: GraspConfig, n: int, seed: int):
    """n feasible pick-points of the scene's object and gripper (seed), as inputs."""
    from mjx_pick.core import pickpoints as pp
    from mjx_pick.engine.backend import make_inputs

    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=grasp)
    if not len(picks):
        raise ConfigError("no feasible pick-point to size Warp's buffers with")
    return make_inputs(scene, grasp, picks)


def rerun_overflowed(backend, inputs, first, run, masks: tuple[int, int], describe):
    """Re-simulate the picks whose buffers overflowed, with doubled buffers, until none
    does (MAX_GROWTH growths at most over the backend's life, then BufferOverflowError):
    no result ever comes from a dropped contact or constraint row.

    Args:
      backend: has ``buffers`` (BufferSizes), ``growths`` and ``stats``; its buffers
        are grown here.
      inputs: the run's PickInputs; first: its (results, traces, Diagnostics).
      run: inputs -> (results, traces, Diagnostics), at the backend's current buffers.
      masks: (contact bits, row bits) of the engine's overflow flags.
      describe: overflow bits -> their names.

    Returns:
      (results, traces, Diagnostics), the re-simulated picks' rows replaced.
    """
    merged, traces, diag = first
    overflowing = masks[0] | masks[1]
    todo = np.flatnonzero(np.asarray(diag.overflow) & overflowing)
    while len(todo):
        seen = int(np.bitwise_or.reduce(diag.overflow[todo]))
        if backend.growths >= MAX_GROWTH:
            raise BufferOverflowError(
                f"Warp's buffers overflowed ({describe(seen)}) in {len(todo)} of {len(inputs)} "
                f"pick-points even at {backend.buffers.contacts} contacts and "
                f"{backend.buffers.rows} constraint rows per simulation; pass larger "
                "BufferSizes (make_backend(..., buffers=...)) or use backend 'mujoco'"
            )
        backend.buffers = backend.buffers.grown(
            contacts=bool(seen & masks[0]), rows=bool(seen & masks[1])
        )
        backend.growths += 1
        log.warning(
            "Warp buffer overflow (%s) in %d pick-points: re-simulating them with %d "
            "contacts and %d constraint rows per simulation",
            describe(seen),
            len(todo),
            backend.buffers.contacts,
            backend.buffers.rows,
        )
        backend.stats.n -= len(todo)  # counted again by the re-run
        out, rows, sub = run(inputs.take(todo))
        for key in merged:
            merged[key][todo] = out[key]
        if traces is not None:
            traces[todo] = rows
        for field, values in zip(diag, sub, strict=True):
            field[todo] = values
        todo = todo[(np.asarray(sub.overflow) & overflowing) != 0]
    return merged, traces, diag
