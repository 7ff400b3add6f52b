"""Output folders that are owned: checked and claimed before any work starts.

Every command that writes a folder (evaluate, sweep, compare, design, robust,
calibrate, picks) first calls :func:`claim`. The folder gets a manifest,
``mjx_pick_run.json``: the command, a hash of its configuration, its status
(running / complete) and when. A later command refuses the folder when another command
wrote it, or the same command with another configuration, unless the user asks to
``overwrite`` (the folder is emptied first) or to ``resume``. A path that cannot hold
results -- a file, a read-only place, a folder that cannot be created -- is refused
with one line naming the path and the reason, before anything is simulated.

When the command ends -- complete, interrupted or cancelled -- :func:`finish` records the
status in the manifest and writes the run's metadata, ``run.json``: the same record
for every command (the merged configuration, package versions, backend, device, seed,
compile / run / wall time, status and when). A command that adds its files to another
command's folder (robust into an evaluate folder) writes ``run-<command>.json`` and
leaves the folder's manifest and ``run.json`` alone.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import platform
import shutil
import sys
import tempfile
from importlib import metadata
from pathlib import Path

from mjx_pick.core.config import ConfigError, write_json

MANIFEST = "mjx_pick_run.json"
RUN = "run.json"  # the run's metadata (see finish)


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
    """True when path holds a complete run of command with this configuration key."""
    m = read_manifest(path) or {}
    return (m.get("command"), m.get("config_key"), m.get("status")) == (command, key, "complete")


def portable_object(summary: dict) -> dict:
    """An object's summary (``ObjectModel.summary``) less where it was read from: what a
    configuration key holds of it, so that the same object from a checkout and from an
    installed package is the same experiment."""
    return {k: v for k, v in summary.items() if k != "source"}


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


def versions() -> dict:
    """Python, platform and the versions of the packages that decide the results."""
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for pkg in ("mjx-pick", "mujoco", "mujoco-mjx", "jax", "jaxlib", "numpy", "warp-lang"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


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
) -> Path:
    """Record that a command's run in `path` ended, and write its metadata.

    Args:
      status: "complete", "interrupted" (Ctrl-C) or "cancelled" (a cancel event).
      command: the command (default: the manifest's, i.e. the folder's owner).
      config: the merged configuration of the run (JSON-able).
      seed, backend, device: what ran ('mujoco', 'cpu:2 threads', ...).
      timing: seconds, e.g. ``engine.Engine.describe()['timing']`` plus wall_s.

    Returns:
      the metadata file: ``run.json``, or ``run-<command>.json`` for a command that
      joined another command's folder (whose manifest is then left as it is).
    """
    path = Path(path)
    now = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    manifest = read_manifest(path) or {}
    command = command or manifest.get("command")
    own = manifest.get("command") in (None, command)
    if own:
        manifest["status"] = status
        manifest["finished"] = now
        write_json(path / MANIFEST, manifest)
    record = {
        "command": command,
        "status": status,
        "config_key": manifest.get("config_key") if own else None,
        "started": manifest.get("started") if own else None,
        "finished": now,
        "seed": seed,
        "backend": backend,
        "device": device,
        "timing": timing,
        "versions": versions(),
        "config": config,
    }
    return write_json(path / (RUN if own else f"run-{command}.json"), record)
