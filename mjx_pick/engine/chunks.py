"""Resume: a run's finished chunks in its output folder, the same way for every command.

Details: docs/engine.md (engine/chunks.py).
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mjx_pick.core.config import ConfigError, to_dict, write_json, write_parquet
from mjx_pick.engine.backend import Backend
from mjx_pick.engine.inputs import PickInputs
from mjx_pick.outputs.rundir import (
    claim,
    config_hash,
    flat_settings,
    is_complete,
    read_manifest,
    remove_recorded,
    result_versions,
    what_changed,
)


class ChunkStore:
    """A run's finished chunks in its output folder (see the module docstring).

    Args:
      out_dir: the run's output folder (already claimed: ``rundir.claim``).
      key: the run's configuration key (the folder's manifest's).
      resume: continue from the chunks there; without it, a folder that holds chunks
        is refused (ConfigError) before anything is simulated, as is one whose chunks
        belong to another configuration.
      command: a command that adds its results to another command's folder (robust
        into an evaluate folder) keeps its chunks apart, under ``chunks/<command>/``:
        the folder's own chunks and manifest are the other command's.
      settings: the settings hashed into key (JSON-able), kept in ``plan.json`` so
        that a refused resume names each setting that changed.
    """

    def __init__(
        self,
        out_dir: str | Path,
        key: str,
        resume: bool = False,
        *,
        command: str | None = None,
        settings: dict | None = None,
    ):
        self.dir = self.folder(out_dir, command)
        self.out_dir = Path(out_dir)
        self.key = key
        self.settings = flat_settings(settings) if settings is not None else None
        has_chunks = any(self.dir.glob("part-*.parquet"))
        saved = self._saved()
        if has_chunks and not resume:
            raise ConfigError(
                f"{out_dir} holds results of an earlier run: pass --resume to continue it, "
                "or choose another --out"
            )
        if has_chunks and (saved is None or "chunk_sizes" not in saved):
            raise ConfigError(
                f"{out_dir} holds chunks without a chunk plan (an older mjx-pick wrote them); "
                "they cannot be resumed: choose another --out or pass --overwrite"
            )
        if has_chunks and saved.get("key") != key:
            changed = what_changed(saved, self.settings) if self.settings is not None else ""
            raise ConfigError(
                f"{out_dir} holds a run with a different configuration{changed}; it cannot be "
                "resumed with these settings (choose another --out)"
            )
        # kind of run -> pick-points per chunk; kept from the folder's chunks when resuming
        self.sizes: dict[str, int] = dict(saved["chunk_sizes"]) if has_chunks else {}
        self.read_chunks = self.written_chunks = 0

    @staticmethod
    def folder(out_dir: str | Path, command: str | None = None) -> Path:
        """Where a run's chunks are kept: ``chunks/``, or ``chunks/<command>/`` for a
        command that joined another command's folder."""
        base = Path(out_dir) / "chunks"
        return base / command if command else base

    @property
    def plan_path(self) -> Path:
        return self.dir / "plan.json"

    def _saved(self) -> dict | None:
        if not self.plan_path.is_file():
            return None
        try:
            return json.loads(self.plan_path.read_text())
        except ValueError as err:
            raise ConfigError(
                f"{self.plan_path}: unreadable chunk plan ({err}); choose another --out"
            ) from err

    def chunk_size(self, kind: str, proposed: int) -> int:
        """Pick-points per chunk for runs of kind: the saved size, else proposed (then
        saved, before any chunk of that kind is simulated)."""
        if int(proposed) < 1:
            raise ConfigError(f"chunk_size = {proposed} is out of range: allowed >= 1")
        if kind not in self.sizes:
            self.sizes[kind] = int(proposed)
            plan = {"key": self.key, "chunk_sizes": self.sizes, "versions": result_versions()}
            if self.settings is not None:
                plan["settings"] = self.settings
            write_json(self.plan_path, plan)
        return self.sizes[kind]

    def path(self, name: str) -> Path:
        """Where chunk `name` is written (the GUI counts these files)."""
        return self.dir / f"part-{name}.parquet"

    def read(self, name: str, rows: int) -> pa.Table | None:
        """Chunk `name` ((rows,) rows), or None when it is not there or unreadable."""
        path = self.path(name)
        if not path.is_file():
            return None
        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as err:
            _unreadable(path, err)
            return None
        if table.num_rows != rows:
            raise ConfigError(f"{path} does not hold this chunk's rows: choose another --out")
        self.read_chunks += 1
        return table

    def write(self, name: str, table: pa.Table) -> None:
        """Save a finished chunk (atomically)."""
        write_parquet(self.path(name), table)
        self.written_chunks += 1

    def for_backend(self, backend: Backend, structure: tuple, rows: np.ndarray) -> BackendChunks:
        """The store as :meth:`Runner.run <mjx_pick.engine.runner.Runner.run>` uses it
        for one run on backend: structure is the compiled simulation's
        (``Settings.structure``), rows a digest of each row's settings ((N,) bytes: its
        variant), in the order of the run's inputs."""
        h = hashlib.sha256(json.dumps(to_dict(structure), sort_keys=True, default=str).encode())
        # a Ray backend's calls are actor batches (its batch_size is one per actor)
        batch = getattr(backend, "call_batch_size", backend.batch_size)
        h.update(f"{backend.name}/{batch}".encode())
        return BackendChunks(self, h.hexdigest()[:16], np.asarray(rows))

    def remove(self) -> None:
        """Drop the chunks once the run's outputs are written (they hold every row): the
        files the run recorded writing there, and chunks/ where that empties it."""
        remove_recorded(self.out_dir, self.dir.relative_to(self.out_dir).as_posix() + "/")


class BackendChunks:
    """A :class:`ChunkStore` seen from one run on one compiled program
    (:meth:`ChunkStore.for_backend`): chunks of result arrays, named by what decides them."""

    def __init__(self, store: ChunkStore, base: str, rows: np.ndarray):
        self.store, self.base, self.rows = store, base, rows

    def chunk_size(self, proposed: int) -> int:
        """This program's chunk size: the saved one, else proposed (then saved)."""
        return self.store.chunk_size(self.base, proposed)

    def _name(self, inputs: PickInputs, rows: slice) -> str:
        h = hashlib.sha256(self.base.encode())
        h.update(np.ascontiguousarray(self.rows[rows]).tobytes())
        # the model fields carried per pick-point are left out: which ones a program
        # carries depends on the variants it ran before, while the row's values of them
        # follow from its settings (hashed above)
        for leaf in inputs.replace(model={}).leaves():
            a = np.ascontiguousarray(leaf)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        return h.hexdigest()[:32]

    def read(self, inputs: PickInputs, rows: slice) -> dict | None:
        """The saved results of the chunk of inputs at rows of the run ((N,) arrays), or None."""
        table = self.store.read(self._name(inputs, rows), len(inputs))
        if table is None:
            return None
        return {k: table[k].to_numpy(zero_copy_only=False) for k in table.column_names}

    def write(self, inputs: PickInputs, rows: slice, results: dict) -> None:
        """Save a simulated chunk's results ((N,) arrays, atomically)."""
        self.store.write(self._name(inputs, rows), pa.table(results))


def row_digests(settings: list, sizes: list[int]) -> np.ndarray:
    """(sum(sizes),) 16-byte digests: job j's settings (a JSON-able value or dataclass),
    repeated for its sizes[j] rows -- a chunk's rows named by their variant."""
    digests = [
        hashlib.sha256(json.dumps(to_dict(s), sort_keys=True, default=str).encode()).digest()[:16]
        for s in settings
    ]
    return np.repeat(np.array(digests, dtype="S16"), sizes)


def open_store(
    out: str | Path | None,
    command: str,
    request: dict,
    *,
    resume: bool,
    overwrite: bool,
    joins: tuple[str, ...] = (),
) -> tuple[ChunkStore | None, bool]:
    """A resumable study's output folder, before it simulates: the folder claimed for
    command under request's configuration key and its :class:`ChunkStore` -- or, on
    resume, whether the folder already holds this study complete (the caller reads it
    back and simulates nothing). Returns (store, complete); (None, False) without out.

    joins: commands whose folder this one may add its results to (``rundir.claim``);
    in such a folder the study's chunks are its own (``chunks/<command>/``), and
    overwrite drops them (not the other command's files)."""
    if out is None:
        return None, False
    key = config_hash(request)
    if resume and not overwrite and is_complete(out, command, key):
        return None, True
    claim(out, command, key, resume=resume, overwrite=overwrite, joins=joins, settings=request)
    joined = (read_manifest(out) or {}).get("command") != command
    if joined and overwrite:
        remove_recorded(out, f"chunks/{command}/")
    own = command if joined else None
    return ChunkStore(out, key, resume, command=own, settings=request), False


def _unreadable(path: Path, err: BaseException) -> None:
    """Say that a saved chunk cannot be read (a disk error, a copy cut short): it is
    simulated again and written over, atomically."""
    print(
        f"mjx-pick: {path}: unreadable chunk ({type(err).__name__}: {err}); simulating it again",
        file=sys.stderr,
    )
