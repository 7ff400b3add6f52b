"""Output folders that are owned: checked and claimed before any work starts.

Details: docs/outputs.md (outputs/rundir.py).
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import datetime
import hashlib
import json
import os
import platform
import shutil
import socket
import sys
import tempfile
import threading
from importlib import metadata
from pathlib import Path

from mjx_pick.core.config import ConfigError, observe_writes, to_dict, write_json

try:
    import fcntl
except ImportError:  # no flock (Windows): folders are claimed without a lock
    fcntl = None

MANIFEST = "mjx_pick_run.json"
LOCK = ".mjx_pick.lock"  # the advisory lock of a folder being written (see claim)
RUN = "run.json"  # the run's metadata (see finish)
# every file the runs in a folder wrote, one JSON string a line, relative to the folder
# (a trailing '/': a folder a run owns whole): the only files mjx-pick ever removes
JOURNAL = ".mjx_pick_files"


def config_hash(config) -> str:
    """A short, stable hash of a JSON-able configuration."""
    text = json.dumps(config, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def read_manifest(path: str | os.PathLike) -> dict | None:
    """The folder's manifest, or None when it has none (or an unreadable one)."""
    f = Path(path) / MANIFEST
    try:
        return json.loads(f.read_text())
    except (OSError, ValueError):
        return None


def is_complete(path: str | os.PathLike, command: str, key: str) -> bool:
    """True when path holds a complete run of command with this configuration key: in
    its own folder (the manifest's), or added to another command's folder (its
    ``run-<command>.json``, see :func:`finish`)."""
    m = read_manifest(path) or {}
    if m.get("command") not in (None, command):
        try:
            m = json.loads((Path(path) / f"run-{command}.json").read_text())
        except (OSError, ValueError):
            return False
    return (m.get("command"), m.get("config_key"), m.get("status")) == (command, key, "complete")


def portable_object(summary: dict) -> dict:
    """An object's summary (``ObjectModel.summary``) less where it was read from: what a
    configuration key holds of it, so that the same object from a checkout and from an
    installed package is the same experiment."""
    return {k: v for k, v in summary.items() if k != "source"}


def check_out(out) -> None:
    """Refuse an output folder given as empty text (an unset shell variable in ``--out
    "$DIR"``), which would otherwise be the current folder."""
    if out is not None and not str(out).strip():
        raise ConfigError(
            f"--out {str(out)!r}: empty; give a folder (an unset variable? to write into the "
            "current folder, say --out .)"
        )


def check_folder(out) -> None:
    """The checks of an output folder that write nothing: not empty text, not a file,
    not a folder of files mjx-pick did not write. ``claim`` makes them first (a
    refused command leaves nothing behind: no lock file in --out / or /etc); an
    interface may make them before other questions (how long a run will take)."""
    if out is None:
        return
    check_out(out)
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--out {path}: is a file, not a folder")
    if path.is_dir() and read_manifest(path) is None:
        _refuse_foreign(path)


def _usable(path: Path) -> None:
    check_folder(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"--out {path}: cannot be created ({err.strerror or err})") from err
    try:  # the one sure test: write a file there (read-only mounts, /proc, quotas)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".mjx_pick_probe."):
            pass
    except OSError as err:
        raise ConfigError(f"--out {path}: cannot be written ({err.strerror or err})") from err


@dataclasses.dataclass
class _Held:
    """A folder this process has claimed and not yet released."""

    fd: int | None  # the open lock file (None where the platform has no flock)
    command: str
    own: bool  # False: joined another command's folder (its manifest is not ours)
    settings: dict | None = None  # a joined command's settings (flat), for its record
    key: str | None = None  # a joined command's configuration key, for its record
    recorded: set[str] = dataclasses.field(default_factory=set)  # in its journal already


_held: dict[Path, _Held] = {}
_atexit_registered = False
_recorders: dict[Path, set[str]] = {}  # folders written without a claim (see recording)
_journal_lock = threading.Lock()  # a run's chunks may be saved from several threads


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


def lock_holder(path: str | os.PathLike) -> dict | None:
    """Who is writing the folder now: the lock file's record (pid, host, command,
    started) of a live process -- this one included -- or None when no process holds
    the folder's lock. A lock file left by a process that died is no holder: the
    kernel drops a flock with the process that held it."""
    path = Path(path)
    held = _held.get(path.resolve())
    if held is not None:
        return {"pid": os.getpid(), "host": socket.gethostname(), "command": held.command}
    lock = path / LOCK
    if fcntl is None or not lock.is_file():
        return None
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _lock_record(lock)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _lock_record(lock: Path) -> dict:
    try:
        return json.loads(lock.read_text()) or {}
    except (OSError, ValueError):  # written a moment after the lock is taken
        return {}


def _busy(path: Path, who: dict) -> ConfigError:
    pid, host = who.get("pid", "unknown"), who.get("host", "an unknown host")
    what = f"`mjx-pick {who['command']}`" if who.get("command") else "another mjx-pick"
    since = f", started {who['started']}" if who.get("started") else ""
    return ConfigError(
        f"--out {path}: {what} is writing this folder now (pid {pid} on {host}{since}); "
        "wait until it ends, or choose another --out"
    )


def _lock(path: Path, command: str, own: bool) -> bool:
    """Take the folder's advisory lock for this process; True when it was taken now
    (False: this process held it already). Raises ConfigError naming the live holder."""
    key = path.resolve()
    if key in _held:
        return False
    fd = None
    if fcntl is not None:
        fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise _busy(path, _lock_record(path / LOCK)) from None
        record = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "command": command,
            "started": _now(),
        }
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(record).encode(), 0)
    _held[key] = _Held(fd, command, own, recorded=set(_journal(path) or ()))
    observe_writes(record_file)
    global _atexit_registered
    if not _atexit_registered:
        atexit.register(end_claims, "failed", "the process ended before the run finished")
        _atexit_registered = True
    return True


def release(path: str | os.PathLike) -> None:
    """Give up this process's lock on a folder (nothing when it holds none). The
    lock file stays: a later writer takes the lock on it."""
    held = _held.pop(Path(path).resolve(), None)
    if held is not None and held.fd is not None:
        fcntl.flock(held.fd, fcntl.LOCK_UN)
        os.close(held.fd)


def end_claims(status: str, message: str) -> list[Path]:
    """Close every folder this process claimed and has not finished: its manifest
    says `status` with `message` (never "running"), and its lock is released. What
    the interfaces call when a command ends by an error or a signal, and what runs at
    exit. Best effort: a folder that cannot be written any more (made read-only) is
    only released -- its manifest then says "running" under no lock, which the next
    claim reads as a run that died. Returns the folders it closed."""
    closed = []
    for key, held in list(_held.items()):
        try:
            if held.own:
                m = read_manifest(key) or {}
                if m.get("status") == "running":
                    finish(key, status, command=held.command, message=message)
            else:
                finish(key, status, command=held.command, message=message)
        except OSError:
            pass
        release(key)
        closed.append(key)
    return closed


def error_message(err: BaseException) -> str:
    """An error as one line for a manifest: a ConfigError's own text, else its type too."""
    if isinstance(err, ConfigError):
        return str(err)
    text = str(err) or "(no message)"
    return f"{type(err).__name__}: {text}"


def fail(path: str | os.PathLike, err: BaseException, command: str | None = None) -> None:
    """Mark a claimed folder "failed" with err's message (never left "running": the
    next claim replaces its files) and release it. Best effort -- it runs while an
    error goes on: a folder that cannot be written any more is only released."""
    try:
        finish(path, "failed", command=command, message=error_message(err))
    except OSError:
        release(path)


def flat_settings(settings, prefix: str = "") -> dict:
    """A configuration as one level of dotted names to JSON values: what a manifest
    records, so that a refusal can name each setting that changed. Long text (a
    simulated model's XML) is kept as its digest."""
    value = to_dict(settings)
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            out.update(flat_settings(v, f"{prefix}{k}."))
        return out if out or not prefix else {prefix[:-1]: {}}
    if isinstance(value, str) and len(value) > 200:
        value = "sha256:" + hashlib.sha256(value.encode()).hexdigest()[:16]
    value = json.loads(json.dumps(value, default=str))
    return {prefix[:-1] if prefix else "value": value}


def _show(v) -> str:
    text = "(not set)" if v is _MISSING else json.dumps(v)
    return text if len(text) <= 60 else text[:57] + "..."


_MISSING = object()


def changed_settings(old: dict | None, new: dict | None) -> list[str]:
    """Each setting that differs, as 'name: old -> new' (in name order)."""
    if old is None or new is None:
        return []
    names = sorted(set(old) | set(new))

    def line(k) -> str:
        a, b = old.get(k, _MISSING), new.get(k, _MISSING)
        if _digest(a) and _digest(b):  # a model or a file by its digest: no hash to read
            return f"{k}: its content changed"
        return f"{k}: {_show(a)} -> {_show(b)}"

    return [line(k) for k in names if old.get(k, _MISSING) != new.get(k, _MISSING)]


def _digest(v) -> bool:
    return isinstance(v, str) and v.startswith("sha256:")


def what_changed(old: dict, settings: dict | None) -> str:
    """What a refusal appends to name the settings that changed, ' -- changed: a: 1 ->
    2; ...', between a record's settings (old["settings"], flat) and settings (flat);
    why it cannot say, or "" when nothing differs."""
    lines = changed_settings(old.get("settings"), settings)
    if not lines:
        if old.get("settings") is None:
            return " (that run did not record its settings)"
        return ""
    shown = "; ".join(lines[:8]) + (f"; and {len(lines) - 8} more" if len(lines) > 8 else "")
    return f" -- changed: {shown}"


def record_file(path: str | os.PathLike, *, whole: bool = False) -> None:
    """Record that this process is about to write path, in the journal of each folder
    it claimed (or records for, :func:`recording`) that holds it: before the first byte
    (a run killed mid-write has recorded its file). ``config.write_atomic`` calls it for
    every file; a writer of its own (orbax's checkpoints) records its folder, whole."""
    if not _held and not _recorders:
        return
    path = Path(path)
    target = Path(os.path.abspath(path.parent)).resolve() / path.name
    folders = [(k, h.recorded) for k, h in _held.items()] + list(_recorders.items())
    for folder, seen in folders:
        try:
            rel = target.relative_to(folder).as_posix()
        except ValueError:
            continue
        if rel in (".", JOURNAL, LOCK):
            continue
        rel += "/" if whole else ""
        with _journal_lock:
            if rel not in seen:
                with open(folder / JOURNAL, "a", encoding="utf-8") as fh:
                    fh.write(json.dumps(rel) + "\n")
                seen.add(rel)


@contextlib.contextmanager
def recording(folder: str | os.PathLike):
    """Record the files written into folder meanwhile in its journal, as a claim does,
    without claiming it: ``report`` adds its pages to a run's folder, and a later
    --overwrite of that run removes them with the run's own files. Nothing is recorded
    for a folder no run owns (no manifest)."""
    key = Path(folder).resolve()
    if read_manifest(key) is None or key in _recorders or key in _held:
        yield
        return
    _recorders[key] = set(_journal(key) or ())
    observe_writes(record_file)
    try:
        yield
    finally:
        _recorders.pop(key, None)


def _journal(path: Path) -> list[str] | None:
    """The entries of path's journal (None: it has none, an older mjx-pick wrote it)."""
    try:
        lines = (path / JOURNAL).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    entries = []
    for line in lines:
        try:
            entry = json.loads(line)
        except ValueError:  # a line cut short by a kill: its file was never begun
            continue
        if isinstance(entry, str):
            entries.append(entry)
    return entries


def _inside(path: Path, rel: str) -> Path | None:
    """path / rel where that is inside path, its links followed (a journal entry never
    reaches out of its folder: no '..', no link to elsewhere); else None."""
    if not rel.strip("/") or ".." in Path(rel).parts or Path(rel).is_absolute():
        return None
    target = path / rel.rstrip("/")
    try:
        target.parent.resolve().relative_to(path.resolve())
    except (ValueError, OSError):
        return None
    return target


def remove_recorded(path: str | os.PathLike, under: str = "") -> None:
    """Remove the files the runs in path recorded writing -- all, those in the folder
    `under` ('/'-terminated) or the one file `under` -- and then the folders that held
    them wherever that leaves them empty. Nothing else is ever removed: a file a user
    put beside them stays."""
    path = Path(path)

    def chosen(entry: str) -> bool:
        return entry == under or (under.endswith("/") or not under) and entry.startswith(under)

    with _journal_lock:
        entries = _journal(path) or []
        gone = [e for e in entries if chosen(e)]
        for rel in gone:
            target = _inside(path, rel)
            if target is None:
                continue
            if rel.endswith("/") and target.is_dir() and not target.is_symlink():
                shutil.rmtree(target, ignore_errors=True)
            elif target.is_symlink() or target.is_file():
                target.unlink(missing_ok=True)
        parents = {p for rel in gone if (t := _inside(path, rel)) for p in t.parents}
        for folder in sorted(parents, key=lambda p: len(p.parts), reverse=True):
            if folder != path and path in folder.parents:
                with contextlib.suppress(OSError):
                    folder.rmdir()  # only where empty: a user's file inside keeps it
        kept = [e for e in entries if not chosen(e)]
        if (path / JOURNAL).exists():
            text = "".join(json.dumps(e) + "\n" for e in kept)
            (path / JOURNAL).write_text(text, encoding="utf-8")
        for held in [*(h.recorded for k, h in _held.items() if k == path.resolve())]:
            held.difference_update(gone)


def _unrecorded(path: Path) -> list[str]:
    """The names at path's top that no run recorded writing (dot files and the folder's
    own manifest and run records aside)."""
    entries = _journal(path) or []
    tops = {e.split("/", 1)[0] for e in entries}
    return sorted(
        p.name + ("/" if p.is_dir() else "")
        for p in path.iterdir()
        if not p.name.startswith(".")
        and p.name not in tops
        and not (p.name in (MANIFEST, RUN) or (p.name.startswith("run-") and p.suffix == ".json"))
    )


def _shown(names: list[str]) -> str:
    return ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")


def _refuse_foreign(path: Path) -> None:
    """Refuse a folder without a manifest that holds files (mjx-pick wrote none of them)."""
    others = [p.name for p in path.iterdir() if not p.name.startswith(".")]
    if others:
        raise ConfigError(
            f"--out {path}: the folder holds files that mjx-pick did not write "
            f"({_shown(sorted(others))}); choose an empty or new folder"
        )


def remove_run(path: str | os.PathLike) -> None:
    """Remove the files path's earlier run recorded writing, before a new run takes
    the folder; said on stderr: what is kept (files no run recorded). A folder an older
    mjx-pick wrote (no journal) is refused: which of its files that run wrote is not known."""
    path = Path(path)
    if _journal(path) is None:
        unknown = _unrecorded(path)
        if unknown:
            raise ConfigError(
                f"--out {path}: holds files of a run by an earlier mjx-pick, which did not "
                f"record the files it wrote ({_shown(unknown)}); mjx-pick removes only files "
                "a run recorded: move them away yourself, or choose another --out"
            )
    remove_recorded(path)
    for name in (MANIFEST, RUN):  # the folder's own record: rundir's, written while held
        (path / name).unlink(missing_ok=True)
    kept = _unrecorded(path)
    if kept:
        print(
            f"mjx-pick: {path}: kept {len(kept)} file(s) no mjx-pick run recorded writing "
            f"({_shown(kept)})",
            file=sys.stderr,
        )


def claim(
    out: str | os.PathLike,
    command: str,
    key: str,
    *,
    resume: bool = False,
    overwrite: bool = False,
    joins: tuple[str, ...] = (),
    settings: dict | None = None,
) -> Path:
    """Check that `out` may take this command's results, lock it and mark it running.

    The folder's advisory lock is held until :func:`finish` (or :func:`end_claims`, or
    the process's end), refusing any other process's claim meanwhile, --overwrite too;
    what may replace a folder's files: docs/outputs.md.

    Args:
      command: the writing command's name ("evaluate", "sweep", ...).
      key: hash of the settings that decide the results (:func:`config_hash`).
      resume: continue the same command and configuration in this folder.
      overwrite: empty a folder this project wrote and start again.
      joins: commands whose folder this one may add its files to (robust adds its
        ranking to an evaluate folder).
      settings: the settings hashed into key (JSON-able), recorded in the manifest
        (:func:`flat_settings`) so that a later refusal names what changed.

    Returns:
      the folder, created.
    """
    if resume and overwrite:
        raise ConfigError("--resume and --overwrite contradict each other: choose one")
    check_out(out)
    path = Path(out)
    _usable(path)
    old = read_manifest(path)
    joined = old is not None and old.get("command") in joins
    taken = _lock(path, command, own=not joined)
    try:
        old = read_manifest(path)  # again, now that no other process writes it
        flat = flat_settings(settings) if settings is not None else None
        _decide(path, command, key, old, joined, taken, resume, overwrite, flat)
    except BaseException:
        if taken:
            release(path)
        raise
    if joined:
        held = _held.get(path.resolve())
        if held is not None:
            held.settings, held.key = flat, key  # recorded in run-<command>.json by finish
        return path  # add to it; its own manifest stays
    _write_running_manifest(path, command, key, flat)
    return path


def _write_running_manifest(path: Path, command: str, key: str, flat: dict | None) -> None:
    """path's manifest for a run that starts now: the command, its configuration key and
    flat settings, status "running", this process and the result-deciding versions."""
    write_json(
        path / MANIFEST,
        {
            "command": command,
            "config_key": key,
            "status": "running",
            "started": _now(),
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "settings": flat,
            "versions": result_versions(),
        },
    )


def _decide(path, command, key, old, joined, taken, resume, overwrite, flat) -> None:
    """claim's checks, under the folder's lock; empties the folder where that is due.

    The one rule for what may replace a folder's files: ``overwrite``, or nothing
    finished there -- a run that failed or died (says "running" under a free lock)
    before it saved a chunk. Finished chunks and complete results are never deleted
    without ``overwrite``: another configuration is refused, naming what changed."""
    if old is None:
        _refuse_foreign(path)  # again, under the lock
        return
    if overwrite:
        if not joined:  # a joined command's own files are replaced by that command
            remove_run(path)
        return
    if joined:
        old = _joined_record(path, command)
        if old is None:
            return
        taken = True  # the folder's lock is ours: a joined run that says running is dead
    status = old.get("status")
    same = (old.get("command"), old.get("config_key")) == (command, key)
    n_chunks = finished_chunks(path, command if joined else None)
    if same:
        if resume or n_chunks:
            check_versions(path, old, command if joined else None)
        return
    # nothing finished to keep: a failed run, or a "running" one no process holds
    abandoned = status == "failed" or (status == "running" and taken)
    if abandoned and not n_chunks:
        why = old.get("message") or "it was stopped before it finished"
        if not joined:
            remove_run(path)
        print(
            f"mjx-pick: {path}: replacing the files of an unfinished `mjx-pick "
            f"{old.get('command')}` run that saved no results ({status}: {why}), those it "
            "recorded writing",
            file=sys.stderr,
        )
        return
    if status == "complete":
        kept = " (complete)"
    else:
        stopped = "a run that died" if status == "running" else f"a run that ended {status}"
        kept = f" ({n_chunks} finished chunks of {stopped})"
    if old.get("command") != command:
        raise ConfigError(
            f"--out {path}: holds the results of `mjx-pick {old.get('command')}`{kept}; "
            "keep them and write elsewhere with --out NEW, or pass --overwrite to delete "
            "them and start again"
        )
    resume_hint = "continue it with its settings and --resume, or " if status != "complete" else ""
    raise ConfigError(
        f"--out {path}: holds `mjx-pick {command}` results of another configuration{kept}"
        f"{what_changed(old, flat)}. Keep them: {resume_hint}write elsewhere with "
        "--out NEW; --overwrite deletes them"
    )


def _joined_record(path: Path, command: str) -> dict | None:
    """What a command that adds its files to another command's folder left there before:
    its ``run-<command>.json``, else its chunk plan (a run that died), else None."""
    for f in (path / f"run-{command}.json", path / "chunks" / command / "plan.json"):
        try:
            record = json.loads(f.read_text())
        except (OSError, ValueError):
            continue
        if f.name == "plan.json":  # chunks without a record: the run died before its end
            record = {
                "command": command,
                "config_key": record.get("key"),
                "status": "running",
                "settings": record.get("settings"),
                "versions": record.get("versions"),
            }
        return record
    return None


def finished_chunks(path: str | os.PathLike, command: str | None = None) -> int:
    """The chunks a run saved in its folder (``chunks/``, or ``chunks/<command>/`` for a
    command that joined another command's folder): finished work, never deleted
    without --overwrite."""
    base = Path(path) / "chunks"
    base = base / command if command else base
    if not base.is_dir():
        return 0
    return sum(1 for p in base.rglob("part-*") if p.suffix in (".parquet", ".npz"))


# the packages whose versions decide a run's numbers: a run is continued only under them
RESULT_PACKAGES = (
    "mjx-pick",
    "mujoco",
    "mujoco-mjx",
    "mujoco-warp",
    "jax",
    "jaxlib",
    "numpy",
    "warp-lang",
)


def result_versions() -> dict:
    """The installed versions of :data:`RESULT_PACKAGES` (None: not installed)."""
    out = {}
    for pkg in RESULT_PACKAGES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def recorded_versions(path: Path, record: dict | None = None) -> dict | None:
    """The package versions a folder's run was made with: its record's (manifest, chunk
    plan), else its ``config.json``'s or ``run.json``'s; None when none says."""
    if record and record.get("versions"):
        return record["versions"]
    for name in ("config.json", RUN):
        try:
            v = json.loads((path / name).read_text()).get("versions")
        except (OSError, ValueError, AttributeError):
            continue
        if v:
            return v
    return None


def version_changes(recorded: dict | None) -> list[str]:
    """Each result-deciding package whose version differs from the installed one, as
    'mujoco 3.1.0 -> 3.3.0' (a package a record does not name is not compared)."""
    if not recorded:
        return []
    now = result_versions()
    return [
        f"{pkg} {recorded[pkg] or 'not installed'} -> {now[pkg] or 'not installed'}"
        for pkg in RESULT_PACKAGES
        if pkg in recorded and recorded[pkg] != now[pkg]
    ]


def check_versions(path: Path, record: dict | None, command: str | None = None) -> None:
    """Refuse to continue a run in path that was made with other package versions: its
    saved results would be merged with results of another engine."""
    changes = version_changes(recorded_versions(Path(path), record))
    if changes:
        raise ConfigError(
            f"--out {path}: its run was made with other package versions ("
            + "; ".join(changes)
            + "): its saved results cannot be continued with these. Keep them and write "
            "elsewhere with --out NEW, or pass --overwrite to delete them and start again"
        )


def versions() -> dict:
    """Python, platform and the versions of the packages that decide the results."""
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    return out | result_versions()


def finish(
    path: str | os.PathLike,
    status: str = "complete",
    *,
    command: str | None = None,
    config: dict | None = None,
    seed: int | None = None,
    backend: str | None = None,
    device: str | None = None,
    timing: dict | None = None,
    message: str | None = None,
    release_lock: bool = True,
    key: str | None = None,
) -> Path:
    """Record that a command's run in `path` ended, and write its metadata (docs/outputs.md).

    Args:
      status: "complete", "interrupted" (Ctrl-C), "terminated" (SIGTERM), "cancelled"
        (a cancel event) or "failed"; message: why it stopped (manifest and run.json).
      release_lock: give up the folder's lock once written; False for a caller that
        still tidies the folder (then :func:`release`).
      command: the command (default: the manifest's, i.e. the folder's owner).
      config (merged, JSON-able), seed, backend ('mujoco'), device ('cpu:2 threads'): what ran.
      timing: seconds, e.g. ``runner.Runner.describe()['timing']`` plus wall_s.
      key: the configuration key of a command that joined another's folder (is_complete).

    Returns:
      ``run.json``, or ``run-<command>.json`` for a command that joined another's folder.
    """
    path = Path(path)
    now = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    manifest = read_manifest(path) or {}
    command = command or manifest.get("command")
    own = manifest.get("command") in (None, command)
    if own:
        _mark_finished(path, manifest, status, now, message)
    held = None if own else _held.get(path.resolve())
    if held is not None and key is None:
        key = held.key  # a joined run stopped early: its claim's key
    record = {
        "command": command,
        "status": status,
        "message": message,
        "config_key": manifest.get("config_key") if own else key,
        "started": manifest.get("started") if own else None,
        "finished": now,
        "seed": seed,
        "backend": backend,
        "device": device,
        "timing": timing,
        "versions": versions(),
        "config": config,
    }
    if held is not None and held.settings is not None:
        record["settings"] = held.settings  # what a later refusal names as changed
    try:
        return write_json(path / (RUN if own else f"run-{command}.json"), record)
    finally:
        if release_lock:
            release(path)


def _mark_finished(path: Path, manifest: dict, status: str, now: str, message) -> None:
    """Rewrites path's manifest (as read: manifest) with the run's end status, when it
    ended (ISO time now) and why (message; an earlier run's message is dropped)."""
    manifest["status"] = status
    manifest["finished"] = now
    manifest.pop("message", None)
    if message:
        manifest["message"] = message
    write_json(path / MANIFEST, manifest)
