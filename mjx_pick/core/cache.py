"""An on-disk cache of pure, expensive results (object and gripper preparation).

Details: docs/model.md (core/cache.py).
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import tempfile
import threading
import warnings
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np

ENV_DIR = "MJX_PICK_CACHE_DIR"
ENV_SWITCH = "MJX_PICK_CACHE"  # "0", "false", "no" or "off": bypassed
ENV_MAX_MB = "MJX_PICK_CACHE_MAX_MB"
DEFAULT_MAX_MB = 2048.0
OBJECT_SHARE = 0.25  # of the size limit, for object results; the rest for JAX's programs
FORMAT = 2  # of an entry's layout; a change makes older entries "another version"
# libraries whose results an entry holds; a new version of one may change them
LIBRARIES = ("mjx-pick", "numpy", "coacd", "trimesh", "shapely", "pymeshfix")
_META = "__meta__"


class CacheWarning(UserWarning):
    """The cache was bypassed (corrupt entry, other version, unwritable folder)."""


def enabled() -> bool:
    """False when ``MJX_PICK_CACHE`` turns the cache off (the CLI's ``--no-cache``)."""
    return os.environ.get(ENV_SWITCH, "1").strip().lower() not in ("0", "false", "no", "off")


def root() -> Path:
    """The cache folder: ``$MJX_PICK_CACHE_DIR``, else the user's cache folder."""
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("mjx-pick", appauthor=False))


def limit_bytes() -> int:
    """The size limit of the whole cache folder, bytes (``$MJX_PICK_CACHE_MAX_MB``)."""
    text = os.environ.get(ENV_MAX_MB)
    try:
        mb = float(text) if text else DEFAULT_MAX_MB
    except ValueError:
        mb = -1.0
    if not mb >= 0:
        warnings.warn(
            f"{ENV_MAX_MB}={text!r} is not a size in MB: using {DEFAULT_MAX_MB:g}",
            CacheWarning,
            stacklevel=2,
        )
        mb = DEFAULT_MAX_MB
    return int(mb * 2**20)


def versions() -> dict[str, str | None]:
    """The versions that are part of every key (this package and its geometry libraries)."""
    return dict(_installed())


@functools.cache
def _installed() -> tuple[tuple[str, str | None], ...]:
    """versions(), asked of the installed packages' metadata once per process (each
    question reads files: tens of milliseconds per entry read or written)."""
    out: dict[str, str | None] = {"format": str(FORMAT)}
    for pkg in LIBRARIES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return tuple(out.items())


def digest(*parts: bytes | str | np.ndarray) -> str:
    """sha256 of byte strings, texts and arrays (an array's dtype and shape included)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            p = a.tobytes()
        elif isinstance(p, str):
            p = p.encode()
        h.update(len(p).to_bytes(8, "little"))
        h.update(p)
    return h.hexdigest()


def code_digest(*modules: str) -> str:
    """sha256 of the named modules' source files (``"mjx_pick.core.scene"``): the code that
    computes an entry, for its key. This package's version changes with a release, not
    with an edit; an entry whose code was edited since it was written is then never found.
    A module without a readable source file is named by its name alone."""
    return _code_digest(tuple(sorted(modules)))


@functools.cache
def _code_digest(modules: tuple[str, ...]) -> str:
    import importlib.util

    h = hashlib.sha256()
    for name in modules:
        h.update(name.encode())
        spec = importlib.util.find_spec(name)
        origin = spec.origin if spec is not None else None
        try:
            h.update(Path(origin).read_bytes() if origin else b"")
        except OSError:
            pass
    return h.hexdigest()


def file_digest(path: str | os.PathLike) -> str:
    """sha256 of a file's content."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class Store:
    """The object-results part of one cache folder (``<root>/objects``).

    Args:
      folder: where entries live.
      limit: most bytes its entries may take; older entries are evicted beyond it.
    """

    def __init__(self, folder: Path, limit: int) -> None:
        self.folder = Path(folder)
        self.limit = int(limit)

    def _warn(self, problem: str, text: str) -> None:
        warn_once(self.folder.parent, problem, f"mjx-pick cache {self.folder}: {text}")

    # ---------------------------------------------------------------- entries
    def path(self, kind: str, key: dict) -> Path:
        """The entry's file for a key. The versions are not in the name: another
        version's entry for the same inputs is found, said once and replaced."""
        text = json.dumps({"kind": kind, "key": key}, sort_keys=True)
        return self.folder / f"{kind}-{digest(text)[:40]}.npz"

    def get(self, kind: str, key: dict) -> dict[str, np.ndarray] | None:
        """The arrays stored under key, or None (absent, corrupt or of another version:
        the last two warn)."""
        path = self.path(kind, key)
        try:
            with np.load(path, allow_pickle=False) as npz:
                arrays = {name: npz[name] for name in npz.files}
        except (FileNotFoundError, NotADirectoryError):
            return None  # absent (a folder that cannot exist warns when written)
        except PermissionError as err:
            self._warn("unreadable", f"cannot be read ({err.strerror or err}); not cached")
            return None
        except Exception as err:  # noqa: BLE001 - any damage to a file: recompute, never crash
            self._warn("corrupt", f"entry {path.name} is unreadable ({err!r}); recomputed")
            return None
        try:
            meta = json.loads(arrays.pop(_META).tobytes().decode())
        except (KeyError, ValueError, UnicodeDecodeError):
            self._warn("corrupt", f"entry {path.name} has no valid header; recomputed")
            return None
        if meta.get("versions") != versions() or meta.get("kind") != kind:
            self._warn(
                "version",
                f"entry {path.name} was made by other versions ({meta.get('versions')}); "
                "recomputed",
            )
            return None
        if meta.get("key") != json.loads(json.dumps(key)):
            self._warn("corrupt", f"entry {path.name} holds another key; recomputed")
            return None
        try:  # least recently used: a read counts as a use
            os.utime(path)
        except OSError:
            pass
        return arrays

    def put(self, kind: str, key: dict, arrays: dict[str, np.ndarray]) -> bool:
        """Store arrays under key (atomically); False when the folder cannot take it."""
        meta = json.dumps({"kind": kind, "key": key, "versions": versions()}, sort_keys=True)
        buf = io.BytesIO()
        np.savez(buf, **arrays, **{_META: np.frombuffer(meta.encode(), np.uint8)})
        payload = buf.getvalue()
        if len(payload) > self.limit:
            return False  # never stored: it would evict everything and still not fit
        path = self.path(kind, key)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.folder, prefix=f".{path.name}.", suffix=".tmp")
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(payload)
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError as err:
            self._warn("unwritable", f"cannot be written ({err.strerror or err}); not cached")
            return False
        self.evict()
        return True

    def entries(self) -> list[os.DirEntry]:
        """The folder's entries (finished ``.npz`` files), any order."""
        try:
            with os.scandir(self.folder) as it:
                return [e for e in it if e.name.endswith(".npz") and e.is_file()]
        except OSError:
            return []

    def size(self) -> int:
        """Bytes the entries take."""
        return sum(_stat_size(e) for e in self.entries())

    def evict(self) -> int:
        """Delete least recently used entries until the rest fit the limit; how many."""
        listed = []
        for e in self.entries():
            try:
                st = e.stat()
            except OSError:
                continue  # deleted by another process meanwhile
            listed.append((st.st_mtime, st.st_size, e.path))
        total = sum(s for _, s, _ in listed)
        removed = 0
        for _, size, path in sorted(listed):
            if total <= self.limit:
                break
            try:
                os.unlink(path)
                removed += 1
            except FileNotFoundError:
                pass  # another process evicted it
            except OSError:
                break  # a folder we may read but not change: keep going uncached
            total -= size
        return removed

    def clear(self) -> int:
        """Delete every entry (and stale temporary files); how many entries."""
        n = 0
        try:
            with os.scandir(self.folder) as it:
                for e in it:
                    if e.is_file() and (e.name.endswith(".npz") or e.name.endswith(".tmp")):
                        os.unlink(e.path)
                        n += e.name.endswith(".npz")
        except FileNotFoundError:
            pass
        return n


def _stat_size(e: os.DirEntry) -> int:
    try:
        return e.stat().st_size
    except OSError:
        return 0


_warned: set[tuple[str, str]] = set()
_warned_lock = threading.Lock()


def warn_once(folder: Path, problem: str, text: str) -> None:
    """One :class:`CacheWarning` per cache folder and kind of problem in a process
    ("unwritable", "corrupt", "version", ...): a bypassed cache is said once, not per entry.
    """
    with _warned_lock:
        if (str(folder), problem) in _warned:
            return
        _warned.add((str(folder), problem))
    warnings.warn(text, CacheWarning, stacklevel=4)


def reset_warnings() -> None:
    """Say every cache problem again, as a new process would (a long-lived worker runs
    each job as if it were one)."""
    with _warned_lock:
        _warned.clear()


_stores: dict[tuple[str, int], Store] = {}


def store() -> Store | None:
    """The object store of the current cache folder, or None when bypassed."""
    if not enabled():
        return None
    folder = root() / "objects"
    limit = int(limit_bytes() * OBJECT_SHARE)
    key = (str(folder), limit)
    if key not in _stores:
        _stores[key] = Store(folder, limit)
    return _stores[key]


def memo(
    kind: str, key: dict, compute: Callable[[], dict[str, np.ndarray]]
) -> dict[str, np.ndarray]:
    """compute()'s arrays, read from the cache when it holds them for key, else computed
    and stored.

    Args:
      kind: what is stored (a short name: part of the entry's file name).
      key: JSON-able; everything that decides the result (content digests, parameters).
        This package's and its geometry libraries' versions are added.
      compute: the pure computation; returns named numpy arrays.
    """
    st = store()
    hit = st.get(kind, key) if st is not None else None
    if hit is not None:
        return hit
    # arrays whether computed or read: the caller sees one type either way
    arrays = {k: np.asarray(v) for k, v in compute().items()}
    if st is not None:
        st.put(kind, key, arrays)
    return arrays


def _folder_usage(folder: Path) -> tuple[int, int]:
    """(files, bytes) under a folder (0, 0 when it does not exist)."""
    files = size = 0
    for dirpath, _, names in os.walk(folder):
        for n in names:
            try:
                size += os.stat(os.path.join(dirpath, n)).st_size
                files += 1
            except OSError:
                pass
    return files, size


def info() -> dict:
    """Where the cache is and what it holds: folder, on/off, entries and bytes of the
    object results and of JAX's compiled programs, and their limits (bytes)."""
    folder = root()
    limit = limit_bytes()
    obj_files = Store(folder / "objects", 0).entries()
    jax_files, jax_bytes = _folder_usage(folder / "jax")
    return {
        "folder": str(folder),
        "enabled": enabled(),
        "objects": {
            "entries": len(obj_files),
            "bytes": sum(_stat_size(e) for e in obj_files),
            "limit_bytes": int(limit * OBJECT_SHARE),
        },
        "compiled": {
            "files": jax_files,
            "bytes": jax_bytes,
            "limit_bytes": limit - int(limit * OBJECT_SHARE),
        },
        "limit_bytes": limit,
    }


def clear() -> dict:
    """Delete the object results and JAX's compiled programs; what was deleted."""
    import shutil

    folder = root()
    objects = Store(folder / "objects", 0).clear()
    files, size = _folder_usage(folder / "jax")
    shutil.rmtree(folder / "jax", ignore_errors=True)
    return {"objects": objects, "compiled_files": files, "compiled_bytes": size}
