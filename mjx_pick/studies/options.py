"""RunOptions: how a study runs, the one value every study carries.

Details: docs/studies.md (studies/options.py).
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from mjx_pick.core import numbers
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.antipodal import AntipodalConfig
from mjx_pick.core.config import ConfigError
from mjx_pick.core.objects import ObjectModel
from mjx_pick.engine.chunks import ChunkStore, open_store
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.simulator import Simulator, marking_stops, study_simulator
from mjx_pick.outputs.rundir import check_out, finish, release


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """How a study runs (the settings every study shares; docs/studies.md).

    n: pick-points per variant, gripper or run (None: the study's default).
    seed: pick-point (and perturbation) seed: same seed, same pick-points.
    pick_config: how pick-points are sampled and checked (None: ``PickConfig()``).
    backend / batch_size: 'auto' or a backend's name (``engine.registry``) /
      simulations per backend call (None: the backend's default).
    out: output folder (None: nothing is written); overwrite: replace what another
      command (or configuration) wrote there; resume: continue an interrupted run of
      the same configuration there; keep_chunks: keep out/chunks/ after a complete run.
    ray: run on a Ray cluster, "auto" or the head's "HOST:PORT" (None: this process).
    progress: show a progress bar on stderr; on_progress: called as (done, total) with
      the pick-points simulated or read back, before the first chunk and after each.
    chunk_size: pick-points per chunk, the unit saved, resumed and cancelled (None: from
      free device memory; on a cluster one actor batch); keep it whole batches.
    cancel: a threading.Event; once set, the run stops before its next chunk.
    on_cluster_event: with ray, called with each ``cluster.ClusterEvent``.
    fixed_costs: seconds spent before the call, by name, first in the summary's ``time_s``.
    grasps: where a study's grasps come from (``grasp_sources``): "topdown" (n
      pick-points, the paper's), "antipodal" (n antipodal grasps on the part's mesh,
      ``antipodal`` their settings), or a grasp file (every grasp in it; depth_mm: the
      tool centre point's distance from the base where the file does not say).
    """

    n: int | None = None
    seed: int = 0
    pick_config: pp.PickConfig | None = None
    backend: str = AUTO
    batch_size: int | None = None
    out: str | Path | None = None
    overwrite: bool = False
    resume: bool = False
    ray: str | None = None
    progress: bool = False
    chunk_size: int | None = None
    keep_chunks: bool = False
    on_progress: Callable[[int, int], None] | None = None
    cancel: threading.Event | None = None
    on_cluster_event: Callable | None = None
    fixed_costs: dict | None = None
    grasps: str = "topdown"
    antipodal: AntipodalConfig | None = None
    depth_mm: float | None = None

    def __post_init__(self):
        # the one rule of each number (core.numbers), as the CLI and the GUI check it
        for name in ("n", "seed", "batch_size", "chunk_size"):
            value = numbers.check_optional(name, getattr(self, name))
            object.__setattr__(self, name, value)
        check_out(self.out)  # out="" is no folder (the current one would be written)
        if self.grasps != "topdown" or self.depth_mm is not None:
            # the grasp source's one check, for every study: before any folder or work
            from mjx_pick.studies.grasp_sources import check_source

            object.__setattr__(self, "grasps", check_source(self.grasps, self.depth_mm))

    @classmethod
    def of(cls, options: RunOptions | None = None, /, **fields) -> RunOptions:
        """options (default: all defaults) with the fields given as keywords replaced;
        a keyword that is not a field is a TypeError, as for any function."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(fields) - names)
        if unknown:
            raise TypeError(f"unexpected keyword argument(s): {', '.join(unknown)}")
        base = options if options is not None else cls()
        return dataclasses.replace(base, **fields) if fields else base

    def n_or(self, default: int) -> int:
        """n, or the study's default when none was given."""
        return int(self.n) if self.n is not None else int(default)

    @property
    def picks(self) -> pp.PickConfig:
        """The pick-point configuration (None and the defaults give one key)."""
        return self.pick_config or pp.PickConfig()

    def check_resume(self) -> None:
        """resume needs an output folder to continue from."""
        if self.resume and self.out is None:
            raise ConfigError("--resume needs --out: the folder of the run to continue")
        if self.resume and not Path(self.out).is_dir():
            raise ConfigError(
                f"--resume: {self.out} does not exist, so there is no run to continue; leave "
                "out --resume to start one there (or check the folder's name)"
            )

    def only(self, study: str, *names: str) -> None:
        """Refuse fields that study does not use (given a value other than the default)."""
        default = RunOptions()
        extra = [
            f.name
            for f in dataclasses.fields(self)
            if f.name not in names and getattr(self, f.name) != getattr(default, f.name)
        ]
        if extra:
            raise ConfigError(f"{study} does not use {', '.join(extra)}")

    @contextlib.contextmanager
    def simulator(
        self, obj: ObjectModel, simulator: Simulator | None = None
    ) -> Iterator[Simulator]:
        """The simulator a study runs on: the caller's (left open), else a new one for
        obj on this backend, batch size and cluster, closed when the study ends."""
        with study_simulator(obj, simulator, self.backend, self.batch_size, self.ray) as sim:
            yield sim

    @contextlib.contextmanager
    def opening(
        self,
        command: str,
        obj: ObjectModel,
        request: dict,
        simulator: Simulator | None = None,
        joins: tuple[str, ...] = (),
    ) -> Iterator[OpenStudy]:
        """The opening every study of simulated variants shares (sweep, compare, design,
        robust): the pick-point raster and resume checked, the simulator made (or the
        caller's), out claimed for command under request's key (``chunks.open_store``;
        joins: commands whose folder it may add to). A run stopped inside marks out
        (``simulator.marking_stops``)."""
        pp.check_raster(obj, self.picks)  # before any allocation or folder
        self.check_resume()
        with self.simulator(obj, simulator) as sim:
            store, complete = open_store(
                self.out, command, request, resume=self.resume, overwrite=self.overwrite,
                joins=joins,
            )  # fmt: skip
            out_dir = Path(self.out) if self.out is not None else None
            with marking_stops(self.out, command):
                yield OpenStudy(command, sim, store, complete, out_dir, self.seed)


def split_fields(request_cls: type, request, options: RunOptions | None, fields: dict):
    """(request, options) of a study: what it computes (a request_cls value, default
    request_cls()) and how it runs, each with the fields given by name replaced (a name
    of neither is a TypeError, as for any function)."""
    what = {f.name for f in dataclasses.fields(request_cls)}
    given = {k: v for k, v in fields.items() if k in what}
    request = request if request is not None else request_cls()
    request = dataclasses.replace(request, **given) if given else request
    opts = RunOptions.of(options, **{k: v for k, v in fields.items() if k not in what})
    return request, opts


@dataclasses.dataclass
class OpenStudy:
    """A study once opened (:meth:`RunOptions.opening`): its simulator, its output
    folder's chunks (None without one) and whether that folder holds it complete
    already (then it is read back, nothing simulated)."""

    command: str
    sim: Simulator
    store: ChunkStore | None
    complete: bool
    out_dir: Path | None
    seed: int

    def close(self, config: dict, meta: dict) -> None:
        """The folder finished (``rundir.finish``: the one metadata writer) once every
        row is in its outputs: its chunks dropped, its lock released."""
        finish(
            self.out_dir, command=self.command, config=config, seed=self.seed,
            release_lock=False, **meta,
        )  # fmt: skip
        self.store.remove()
        release(self.out_dir)
