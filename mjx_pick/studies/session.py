"""A warm process for repeated answers: objects, scenes and backends kept between calls.

Details: docs/engine.md (studies/session.py).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel, load_object
from mjx_pick.engine.backend import Backend
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.runner import Runner
from mjx_pick.engine.simulator import Simulator
from mjx_pick.studies.evaluation import EvaluateRequest, Evaluation, evaluate
from mjx_pick.studies.options import RunOptions, split_fields


class Session:
    """Evaluations in one process that share its objects, scenes and backends.

    Each :meth:`evaluate` is :func:`~mjx_pick.studies.evaluation.evaluate` (the one
    pipeline: checks, output folders, resume, summary) run on the session's simulator of
    its object, whose runner and backends stay open between calls. The first call on a
    part pays what a new process pays (the engine's start, the scene, the backend and
    its compiled programs); a later call on the same part whose settings share a
    compiled program (the same model structure: another contact, force, speed, seed or
    set of pick-points, ``engine.variants``) pays its pick-points and their simulation.
    Results are those of a new process's run of the same call.

    Other studies run on the same warm backends through :meth:`simulator`
    (``sweep(obj, ..., simulator=session.simulator(obj))``, as for ``compare``,
    ``design_search``, ``robustness``, ``min_grip_force``).

    Args:
      backend: 'auto' or a backend's name (``engine.registry``), for every call.
      batch_size: simulations per backend call (None: the backend's default).
      nthread, devices, options: as :class:`~mjx_pick.engine.runner.Runner`'s (C-engine
        threads; the devices a GPU backend uses; the backend's options).

    Use it as a context manager, or call :meth:`close`: it holds the backends'
    memory (on a GPU, their device buffers) until then.
    """

    def __init__(
        self,
        backend: str = AUTO,
        batch_size: int | None = None,
        *,
        nthread: int | None = None,
        devices=None,
        **options,
    ) -> None:
        self.runner = Runner(backend, batch_size, nthread=nthread, devices=devices, **options)
        self._objects: dict[tuple, ObjectModel] = {}  # (source, options, file) -> object
        self._simulators: dict[int, Simulator] = {}  # id(object) -> its simulator

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the backends and every object, scene and simulator kept."""
        self.runner.close()
        self.runner.backends.clear()
        self._simulators.clear()
        self._objects.clear()

    @property
    def backends(self) -> list[Backend]:
        """Every backend built so far, in the order built (one per compiled program)."""
        return list(self.runner.backends)

    def object(self, source: str | os.PathLike, **options) -> ObjectModel:
        """``load_object(source, **options)``, kept: the same source and options give the
        same ObjectModel again, until its file changes (its size or modification time).
        """
        key = (str(source), _options_key(options), _file_stamp(source))
        if key not in self._objects:
            self._objects[key] = load_object(source, **options)
        return self._objects[key]

    def simulator(self, obj: ObjectModel) -> Simulator:
        """The session's simulator of obj (made on first use; kept with obj): its scenes
        and backends serve every later call on obj."""
        if not isinstance(obj, ObjectModel):
            raise ConfigError(
                f"Session.simulator takes an ObjectModel, not {type(obj).__name__}: load it "
                "with session.object(...)"
            )
        sim = self._simulators.get(id(obj))
        if sim is None or sim.object is not obj:
            sim = self._simulators[id(obj)] = Simulator(obj, runner=self.runner)
        return sim

    def evaluate(
        self,
        obj: ObjectModel | str | os.PathLike,
        gripper: GripperSpec | str = "robotiq-2f85",
        options: RunOptions | None = None,
        *,
        request: EvaluateRequest | None = None,
        **fields,
    ) -> Evaluation:
        """:func:`~mjx_pick.studies.evaluation.evaluate` on the session's backends.

        Args:
          obj: an ObjectModel, or a shipped asset name or a file, loaded with
            :meth:`object` (its defaults; other options: ``session.object(path, ...)``).
          gripper, options, request, fields: as evaluate's; the backend and batch size
            are the session's (a different one is refused), and it runs in this process
            (no ``ray``).
        """
        t_object = time.perf_counter()
        if not isinstance(obj, ObjectModel):
            obj = self.object(obj)
        req, opts = split_fields(EvaluateRequest, request, options, fields)
        costs = dict(opts.fixed_costs or {})
        costs.setdefault("object_s", time.perf_counter() - t_object)
        opts = RunOptions.of(opts, fixed_costs=costs)
        return evaluate(obj, gripper, opts, request=req, simulator=self.simulator(obj))


def _file_stamp(source) -> tuple:
    """(size, modification time in ns) of a file source; () for a shipped asset's name."""
    try:
        st = Path(source).stat()
    except (OSError, ValueError):
        return ()
    return (st.st_size, st.st_mtime_ns)


def _options_key(options: dict) -> tuple:
    """load_object's options as a hashable key (an array by its dtype, shape and bytes)."""
    out = []
    for name in sorted(options):
        value = options[name]
        if isinstance(value, np.ndarray):
            value = (value.dtype.str, value.shape, value.tobytes())
        out.append((name, value))
    return tuple(out)
