"""The study-facing simulator: what sweep, compare, design, robustness, minimum force
and calibration run their (settings, pick-points) jobs through.

Details: docs/engine.md (engine/simulator.py).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.core.settings import Settings
from mjx_pick.engine import interrupts
from mjx_pick.engine.backend import Backend
from mjx_pick.engine.chunks import ChunkStore, row_digests
from mjx_pick.engine.inputs import PickInputs, pick_inputs, scene_contact, scene_of
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.runner import Cancelled, ProgressFn, Runner
from mjx_pick.engine.variants import (
    carried_fields,
    program_key,
    varying_fields,
    with_model_fields,
)
from mjx_pick.outputs.progress import ProgressBar
from mjx_pick.outputs.rundir import finish


@contextlib.contextmanager
def marking_stops(out_dir: str | Path | None, command: str) -> Iterator[None]:
    """Inside it, a run stopped by a cancel event (:class:`Cancelled`) or Ctrl-C marks
    the command's output folder "cancelled", "interrupted" or "terminated" (SIGTERM)
    before the stop goes on:
    a folder must never be left saying "running" (out_dir None: nothing to mark)."""
    try:
        yield
    except (Cancelled, KeyboardInterrupt) as stop:
        if out_dir is not None:
            status, message = interrupts.stop_status(stop)
            finish(out_dir, status, command=command, message=message)
        raise


@contextlib.contextmanager
def showing_progress(
    runner: Runner, desc: str, unit: str = "sim", enabled: bool = True
) -> Iterator[ProgressBar | None]:
    """Inside it, the runner's progress goes to a :class:`~mjx_pick.outputs.progress.ProgressBar`
    (on stderr): every run through the runner adds to the one bar. Nothing is shown when
    not enabled or when the runner already reports to someone (an outer study's bar, a
    caller's callback)."""
    if not enabled or runner.on_progress is not None:
        yield None
        return
    with ProgressBar(desc, unit) as bar:
        runner.on_progress = bar
        try:
            yield bar
        finally:
            runner.on_progress = None


class Simulator:
    """Runs (Settings, GraspBatch) jobs for one object, batching what can share a program.

    Jobs whose scenes share a compiled program (``variants.program_key``: contact and
    controller settings always; gripper variants of one model structure, their differing
    model fields carried per pick-point) run as ONE batch of pick-points x variants: one
    compile, one runner call. Another structure gets a backend of its own. Scenes and
    backends are cached: a loop that calls ``run`` again compiles nothing new
    (docs/engine.md).

    Args:
      obj: the object every job simulates.
      backend, batch_size: as :class:`Runner` (ignored when runner is given).
      runner: run through this runner (its backend choice, progress and cancel event).
      ray: run on a Ray cluster ("auto" or "HOST:PORT": ``cluster.ray_runner``; ignored
        when runner is given); :meth:`close` ends its actors.
      on_progress: the runner's progress callback, ``(done, total)`` in pick-point
        simulations of each :meth:`run` (ignored when runner is given).
    """

    def __init__(
        self,
        obj: ObjectModel,
        backend: str = AUTO,
        batch_size: int | None = None,
        *,
        runner: Runner | None = None,
        ray: str | None = None,
        on_progress: ProgressFn | None = None,
    ) -> None:
        self.object = obj
        if runner is None and ray is not None:
            from mjx_pick.engine.cluster import ray_runner

            runner = ray_runner(ray, backend, batch_size, on_progress=on_progress)
        self.runner = runner or Runner(backend, batch_size, on_progress=on_progress)
        self.backend_name = self.runner.backend_name
        self.batch_size = self.runner.batch_size
        self._scenes: dict[tuple, Scene] = {}  # Settings.structure() -> its scene
        self._exact: dict[Settings, Scene] = {}  # Settings -> their own scene
        self._keys: dict[tuple, tuple] = {}  # Settings.structure() -> program_key
        self._backends: dict[tuple, Backend] = {}  # program_key -> backend
        # program_key -> the model fields its runs carry so far: a set that only grows,
        # so that later runs (a design search's rounds) call the same compiled program
        self._carried: dict[tuple, tuple[str, ...]] = {}
        self.rollouts = 0  # pick-point simulations run so far

    def close(self) -> None:
        """Release the runner's resources (a Ray cluster's actors)."""
        self.runner.close()

    @property
    def backends(self) -> list[Backend]:
        """The backends built so far: one per program (one compile each on MJX/Warp)."""
        return list(self._backends.values())

    @property
    def scenes(self) -> int:
        """Scenes compiled so far (one per gripper, solver and grasp height seen)."""
        return len(self._scenes)

    def adopt(self, settings: Settings, backend: Backend) -> None:
        """Reuse a backend built elsewhere for settings' scene (no new compile)."""
        self._scenes[settings.structure()] = backend.scene
        self._backends[self._program(settings)] = backend
        self.runner.adopt(backend)

    def scene(self, settings: Settings) -> Scene:
        """The compiled scene of settings' model structure (cached by
        ``Settings.structure``: the first scene of that structure, whose contact-pair
        values may be other settings'; :meth:`inputs` writes settings' own)."""
        key = settings.structure()
        if key not in self._scenes:
            self._scenes[key] = scene_of(self.object, settings)
        return self._scenes[key]

    def exact_scene(self, settings: Settings) -> Scene:
        """settings' own scene, their contact values in its pairs (cached by settings):
        what an evaluation records (its scene.xml, its resume key). The first of its
        structure is also :meth:`scene`'s."""
        if settings not in self._exact:
            # a scene is its structure's and its MuJoCo contact values (docs/engine.md):
            # settings that differ only in the controller or the phases share one
            scene = self._scenes.get(settings.structure())
            if scene is None or scene.contact != scene_contact(
                scene, settings.contact, settings.solver
            ):
                scene = scene_of(self.object, settings)
            self._exact[settings] = scene
            self._scenes.setdefault(settings.structure(), scene)
        return self._exact[settings]

    def _program(self, settings: Settings) -> tuple:
        key = settings.structure()
        if key not in self._keys:
            name = self.runner.backend_name
            self._keys[key] = program_key(self.scene(settings), settings.grasp, name)
        return self._keys[key]

    def backend(self, settings: Settings) -> Backend:
        """The backend settings run on: the one of their program, built on first use
        from the first scene of that program."""
        key = self._program(settings)
        if key not in self._backends:
            self._backends[key] = self.runner.make(self.scene(settings), settings.grasp)
        return self._backends[key]

    def inputs(self, settings: Settings, picks: GraspBatch) -> PickInputs:
        """picks' inputs under settings for their program's backend (:meth:`backend`):
        the start, contact and controller values of settings, and the model fields in
        which their scene differs from the backend's (carried per pick-point)."""
        program = self._program(settings)
        return self._program_inputs(program, self.backend(settings), [(settings, picks)])

    def chunks(self, settings: Settings):
        """What runs an evaluation's chunks under settings on their program's backend
        (``Runner.chunks``, in this process): chunk by chunk, each pick-point's inputs
        :meth:`inputs`', the results' gripper settings'."""
        backend = self.backend(settings)
        return self.runner.chunks(
            backend,
            settings.grasp,
            lambda picks: self.inputs(settings, picks),
            settings.gripper,
        )

    def run(
        self, jobs: list[tuple[Settings, GraspBatch]], store: ChunkStore | None = None
    ) -> list[dict]:
        """Per-job results (the dict of ``kernels.grasp.finalize``, (len(picks),) arrays).

        The runner's on_progress gets (done, total) over all jobs of this call. store:
        chunks finished by an earlier run are read from it, new ones saved to it
        (``chunks.ChunkStore``: a chunk is named by its rows' settings and inputs).
        """
        for settings, _ in jobs:
            settings.grasp.check_gripper(settings.gripper)
        groups: dict[tuple, list[int]] = {}
        for j, (settings, _) in enumerate(jobs):
            groups.setdefault(self._program(settings), []).append(j)
        results: list[dict | None] = [None] * len(jobs)
        total = sum(len(p) for _, p in jobs)
        done = 0
        report = self.runner.on_progress
        if report is not None:
            report(0, total)
        for program, members in groups.items():
            live = [j for j in members if len(jobs[j][1])]
            for j in members:
                if not len(jobs[j][1]):
                    results[j] = {}
            if not live:
                continue
            offset = done

            def progress(k: int, _n: int, offset=offset) -> None:
                # a group's start (k = 0) is where the previous one ended: said already
                if report is not None and k > 0:
                    report(offset + k, total)

            out, n_run = self._run_program(program, [jobs[j] for j in live], store, progress)
            done += n_run
            self.rollouts += n_run
            start = 0
            for j in live:
                n = len(jobs[j][1])
                results[j] = {k: v[start : start + n] for k, v in out.items()}
                start += n
        return results

    def _run_program(
        self,
        program: tuple,
        jobs: list[tuple[Settings, GraspBatch]],
        store: ChunkStore | None,
        progress: ProgressFn,
    ) -> tuple[dict, int]:
        """One program's jobs (none empty) as one runner call: (their results joined,
        (M,) arrays in the jobs' order; M, the pick-point simulations run)."""
        backend = self.backend(jobs[0][0])
        structure = jobs[0][0].structure()
        inputs = self._program_inputs(program, backend, jobs)
        view = None
        if store is not None:
            rows = row_digests([settings for settings, _ in jobs], [len(p) for _, p in jobs])
            view = store.for_backend(backend, structure, rows)
        out = self.runner.run(backend, inputs, on_progress=progress, store=view).results
        return out, len(inputs)

    def _program_inputs(
        self, program: tuple, backend: Backend, jobs: list[tuple[Settings, GraspBatch]]
    ) -> PickInputs:
        """The jobs' inputs, each from its own scene, as one batch: every variant's
        pick-points' start, contact and controller parameters and model fields."""
        scenes = [self.scene(settings) for settings, _ in jobs]
        # the model fields in which this run's variants differ from the backend's
        # scene, added to those carried before (same program, same inputs' shapes)
        carried = set(self._carried.get(program, ()))
        fields = carried_fields(self.runner.backend_name)
        carried |= set(varying_fields(backend.scene.model, [s.model for s in scenes], fields))
        self._carried[program] = names = tuple(sorted(carried))
        parts = []
        for (settings, picks), scene in zip(jobs, scenes, strict=True):
            part = pick_inputs(scene, settings, picks)
            parts.append(with_model_fields(part, scene.model, names) if names else part)
        return PickInputs.concat(parts)


@contextlib.contextmanager
def study_simulator(
    obj: ObjectModel,
    simulator: Simulator | None = None,
    backend: str = AUTO,
    batch_size: int | None = None,
    ray: str | None = None,
) -> Iterator[Simulator]:
    """The simulator a study runs on: the caller's (left open: it may serve further
    studies), else a new one for obj -- on a Ray cluster with ray -- closed when the
    study ends (a cluster's actors released)."""
    if simulator is not None:
        yield simulator
        return
    sim = Simulator(obj, backend, batch_size, ray=ray)
    try:
        yield sim
    finally:
        sim.close()


def differentiable_rollout(scene: Scene, grasp: GraspConfig, record: bool):
    """The batched MJX rollout (JAX physics) as a JAX function, for forward-mode derivatives.

    (qpos0 (N, nq), params (fields (N,)), pair_friction (N, npair, 5), pair_solref
    (N, npair, 2), pair_solimp (N, npair, 5)) -> (results of (N,) arrays, traces
    (N, T, F) or None), every pick run for all ``grasp.n_ticks()`` control periods.

    Why calibration's ``jax.jacfwd`` calls this and not :meth:`Runner.run`: a
    derivative needs the whole rollout inside the caller's trace, while a backend's
    ``run`` hands back numpy arrays after the device finished (the trace ends there),
    splits the work into chunks and batches on the host, may refill slots (Warp, which
    has no derivatives at all) and records timing as it goes. It is the very program
    ``MjxBackend`` compiles for full-length batches (``mjx_backend.make_rollout``), so
    its values are ``MjxBackend``'s.
    """
    from mjx_pick.engine.mjx_backend import make_rollout

    return make_rollout(scene, grasp, record)
