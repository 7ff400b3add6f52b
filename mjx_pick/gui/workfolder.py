"""The work folder's files as the page reads, lists and serves them: inside it only.

The server may be reachable beyond this machine, and a run folder may hold a link
(``ln -s /etc/passwd report.html``): every file the page reads, lists or serves passes
:func:`confined` -- its path with every link followed must lie inside the work folder --
or is refused with its name and where it leads. One check, used by every route.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from mjx_pick.core.config import ConfigError


class OutsideWorkFolder(ConfigError):
    """A file or folder of the page leads outside the work folder (through a link)."""


def confined(path: str | os.PathLike, workdir: str | os.PathLike) -> Path:
    """path with every link followed, if it lies inside workdir (or is it); else
    OutsideWorkFolder naming path (as the page names it) and where it leads. A path
    that does not exist is checked as far as it resolves (a file about to be written)."""
    base = Path(workdir).absolute()
    root = base.resolve()
    given = Path(path)
    full = (given if given.is_absolute() else base / given).resolve()
    if full == root or root in full.parents:
        return full
    shown = str(given)
    for r in (base, root):  # as the page names a file of the work folder: relative to it
        try:
            shown = str((given if given.is_absolute() else base / given).relative_to(r))
            break
        except ValueError:
            continue
    raise OutsideWorkFolder(
        f"{shown}: a link that leads outside the work folder, to {full}; the page reads and "
        f"serves only files inside the work folder ({root}): remove the link, or copy the "
        "file in"
    )


def inside(path: str | os.PathLike, workdir: str | os.PathLike) -> Path | None:
    """:func:`confined`'s path, or None where it leads outside."""
    try:
        return confined(path, workdir)
    except OutsideWorkFolder:
        return None


def check_tree(folder: str | os.PathLike, workdir: str | os.PathLike) -> Path:
    """folder, checked whole before the page reads it through a library (a run's
    tables, traces, scene): the folder and every file and folder under it -- links
    followed, and the folders they lead to walked too -- inside workdir; else
    OutsideWorkFolder naming the first that is not."""
    top = confined(folder, workdir)
    seen: set[Path] = set()
    todo = [Path(folder)]
    while todo:
        here = todo.pop()
        real = confined(here, workdir)
        if real in seen or not real.is_dir():
            continue
        seen.add(real)
        for entry in sorted(here.iterdir()):
            if entry.is_symlink():
                confined(entry, workdir)
            if entry.is_dir():
                todo.append(entry)
    return top


def read_bytes(path: str | os.PathLike, workdir: str | os.PathLike) -> bytes:
    """A file of the work folder, checked by :func:`confined` first, then read from the
    path it resolved to without following a link there: one made between the check and
    the read is refused (OSError), not followed."""
    real = confined(path, workdir)
    fd = os.open(real, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    with os.fdopen(fd, "rb") as fh:
        return fh.read()


def read_text(path: str | os.PathLike, workdir: str | os.PathLike) -> str:
    """A text file of the work folder (UTF-8, undecodable bytes replaced), checked."""
    return read_bytes(path, workdir).decode("utf-8", errors="replace")


def read_json(path: str | os.PathLike, workdir: str | os.PathLike):
    """A JSON file of the work folder, checked (OSError, ValueError as json's)."""
    return json.loads(read_text(path, workdir))


def json_or_none(path: str | os.PathLike, workdir: str | os.PathLike):
    """A JSON file a run writes atomically, or None while it is not there, not yet
    whole -- or leads outside the work folder (never read then)."""
    try:
        return read_json(path, workdir)
    except (OSError, ValueError):  # OutsideWorkFolder is a ValueError
        return None


def run_folders(workdir: str | os.PathLike) -> tuple[list[Path], list[str]]:
    """The work folder's folders the page may list as runs: (those that lie inside it,
    sorted by name; why each other is left out). A folder reached through a link that
    leads outside is never read."""
    root = Path(workdir)
    kept, left = [], []
    if not root.is_dir():
        return kept, left
    for p in sorted(root.iterdir()):
        try:
            if confined(p, root).is_dir():
                kept.append(p)
        except OutsideWorkFolder as err:
            left.append(str(err))
    return kept, left


def manifest(folder: str | os.PathLike, workdir: str | os.PathLike) -> dict | None:
    """A run folder's manifest (``rundir.read_manifest``), or None when it has none, or
    when the folder or the manifest leads outside the work folder."""
    from mjx_pick.outputs.rundir import MANIFEST, read_manifest

    if inside(folder, workdir) is None or inside(Path(folder) / MANIFEST, workdir) is None:
        return None
    return read_manifest(folder)


def lock_holder(folder: str | os.PathLike, workdir: str | os.PathLike) -> dict | None:
    """Who writes a run folder now (``rundir.lock_holder``: its lock file's record), or
    None -- also when the folder or its lock file leads outside the work folder."""
    from mjx_pick.outputs.rundir import LOCK
    from mjx_pick.outputs.rundir import lock_holder as holder

    if inside(folder, workdir) is None or inside(Path(folder) / LOCK, workdir) is None:
        return None
    return holder(folder)
