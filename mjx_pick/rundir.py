"""Output folders that are owned: checked and claimed before any work starts.

Every command that writes a folder (evaluate, sweep, compare, design, robust,
calibrate, picks) first calls :func:`claim`. The folder gets a manifest,
``mjx_pick_run.json``: the command, a hash of its configuration, its status
(running / complete) and when. A later command refuses the folder when another command
wrote it, or the same command with another configuration, unless the user asks to
``overwrite`` (the folder is emptied first) or to ``resume``. A path that cannot hold
results -- a file, a read-only place, a folder that cannot be created -- is refused
with one line naming the path and the reason, before anything is simulated.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from mjx_pick.config import ConfigError, write_json

MANIFEST = "mjx_pick_run.json"


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


def _usable(path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--out {path}: is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"--out {path}: cannot be created ({err.strerror or err})") from err
    try:  # the one sure test: write a file there (read-only mounts, /proc, quotas)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".mjx_pick_probe."):
            pass
    except OSError as err:
        raise ConfigError(f"--out {path}: cannot be written ({err.strerror or err})") from err


def claim(
    out: str | os.PathLike,
    command: str,
    key: str,
    *,
    resume: bool = False,
    overwrite: bool = False,
    joins: tuple[str, ...] = (),
) -> Path:
    """Check that `out` may take this command's results, and mark it as running.

    Args:
      command: the writing command's name ("evaluate", "sweep", ...).
      key: hash of the settings that decide the results (:func:`config_hash`).
      resume: continue the same command and configuration in this folder.
      overwrite: empty a folder this project wrote and start again.
      joins: commands whose folder this one may add its files to (robust adds its
        ranking to an evaluate folder).

    Returns:
      the folder, created.
    """
    if resume and overwrite:
        raise ConfigError("--resume and --overwrite contradict each other: choose one")
    path = Path(out)
    _usable(path)
    old = read_manifest(path)
    others = [p for p in path.iterdir() if p.name != MANIFEST and not p.name.startswith(".")]
    if old is None and others:
        raise ConfigError(
            f"--out {path}: the folder holds files that mjx-pick did not write; choose an "
            "empty or new folder"
        )
    if old is not None and old.get("command") in joins:
        return path  # add to it; its own manifest stays
    if old is not None and not overwrite:
        if old.get("command") != command:
            raise ConfigError(
                f"--out {path}: holds the results of `mjx-pick {old.get('command')}`; choose "
                f"another folder, or pass --overwrite to replace them"
            )
        if old.get("config_key") != key:
            raise ConfigError(
                f"--out {path}: holds `mjx-pick {command}` results of another configuration; "
                "choose another folder, or pass --overwrite to replace them"
            )
    if old is not None and overwrite:
        for p in others:
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
    write_json(
        path / MANIFEST,
        {
            "command": command,
            "config_key": key,
            "status": "running",
            "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        },
    )
    return path


def finish(path: str | os.PathLike, status: str = "complete") -> None:
    """Record that the command that claimed `path` ended (complete, or interrupted)."""
    manifest = read_manifest(path) or {}
    manifest["status"] = status
    manifest["finished"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    write_json(Path(path) / MANIFEST, manifest)
