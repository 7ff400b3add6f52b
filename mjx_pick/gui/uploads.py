"""Uploaded files: which are accepted, and where they are stored (no web framework).

Every upload of the page is checked here before it is used: an object (image or mesh),
a gripper TOML (tab 2) and an outcomes CSV (the calibration study). Stored files never
replace another file's content.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError, write_atomic
from mjx_pick.core.objects import IMAGE_SUFFIXES, MESH_SUFFIXES

IMAGE_MAX_BYTES = 20 * 2**20
MESH_MAX_BYTES = 50 * 2**20  # also the browser's limit for an object upload
TOML_MAX_BYTES = 64 * 2**10
OUTCOMES_MAX_BYTES = 5 * 2**20
GRASPS_MAX_BYTES = 50 * 2**20  # a grasp file (ACRONYM's HDF5 of 2,000 grasps: ~1 MB)
UPLOAD_TYPES = IMAGE_SUFFIXES + MESH_SUFFIXES


def save_upload(data: bytes, name: str, folder: Path, workdir: Path | None = None) -> Path:
    """An uploaded file under folder, atomically; never replaces another file's content,
    and never reads one a link leads to outside workdir (default: folder) -- that name
    is passed over."""
    from mjx_pick.gui.workfolder import confined, inside

    workdir = folder if workdir is None else workdir
    confined(folder, workdir)  # the uploads folder itself: never one a link leads out
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(name).stem)[:60] or "upload"
    suffix = Path(name).suffix.lower()
    for k in range(1000):
        path = folder / (f"{stem}{suffix}" if k == 0 else f"{stem}-{k + 1}{suffix}")
        if not path.exists() and not path.is_symlink():
            return write_atomic(path, data)
        if inside(path, workdir) is None:  # a link out: neither read nor replaced
            continue
        if path.read_bytes() == data:
            return path  # the same file uploaded again
    raise ConfigError(f"too many uploads named {name!r} in {folder}")


def _too_large(name: str, size: int, limit: int) -> str:
    said, most = _megabytes(size), _megabytes(limit)
    (a, unit), (b, limit_unit) = said.split(), most.split()
    if unit == limit_unit and float(a) <= float(b):  # rounded to the limit: in bytes
        said, most = f"{size:,} bytes", f"{limit:,} bytes"
    return f"{name}: {said} is too large (at most {most})"


def _megabytes(size: int) -> str:
    """A file size as the page writes it: '60.0 MB', '64 KB'."""
    if size >= 2**20:
        return f"{size / 2**20:.1f} MB" if size % 2**20 else f"{size // 2**20} MB"
    return f"{size / 2**10:.1f} KB" if size % 2**10 else f"{size // 2**10} KB"


# Each upload's refusal of a file by its name and size: what the server says after it
# received the file, and what the page says for a file the browser refused to send (by
# the same limits, given to it as `accept` and the largest size): one rule, one message


def object_refused(name: str, size: int) -> str:
    """Why an object file (image or mesh) is refused by its type or size ('' if not)."""
    suffix = Path(name).suffix.lower()
    if suffix not in UPLOAD_TYPES:
        return (
            f"{name}: not an image ({', '.join(IMAGE_SUFFIXES)}) or a mesh "
            f"({', '.join(MESH_SUFFIXES)})"
        )
    limit = IMAGE_MAX_BYTES if suffix in IMAGE_SUFFIXES else MESH_MAX_BYTES
    if size > limit:
        return _too_large(name, size, limit)
    if size == 0:
        return f"{name}: the file is empty"
    return ""


def check_upload(name: str, size: int, data: bytes | None = None) -> str:
    """Why an uploaded object file is refused ('' when it is accepted)."""
    problem = object_refused(name, size)
    if problem:
        return problem
    suffix = Path(name).suffix.lower()
    if data is not None and suffix in IMAGE_SUFFIXES:
        import cv2

        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            return f"{name}: cannot be read as an image (is it really a {suffix[1:].upper()}?)"
    return ""


def toml_refused(name: str, size: int) -> str:
    """Why a gripper TOML is refused by its name or size ('' if not)."""
    if not name.lower().endswith(".toml"):
        return f"{name}: not a .toml file"
    if size > TOML_MAX_BYTES:
        return _too_large(name, size, TOML_MAX_BYTES)
    return ""


def check_toml_upload(name: str, data: bytes) -> str:
    """Why an uploaded gripper TOML is refused before it is parsed ('' when accepted)."""
    return toml_refused(name, len(data))


def outcomes_refused(name: str, size: int) -> str:
    """Why an outcomes CSV is refused by its name or size ('' if not)."""
    if not name.lower().endswith(".csv"):
        return f"{name}: not a .csv file"
    if size > OUTCOMES_MAX_BYTES:
        return _too_large(name, size, OUTCOMES_MAX_BYTES)
    return ""


def check_outcomes_upload(name: str, data: bytes) -> str:
    """Why an uploaded outcomes CSV is refused before it is read ('' when accepted)."""
    problem = outcomes_refused(name, len(data))
    if problem:
        return problem
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return f"{name}: not a UTF-8 text file"
    return ""


def grasps_refused(name: str, size: int) -> str:
    """Why a grasp file is refused by its name or size ('' if not): the formats the
    library reads, by suffix (``gui.grasp_input.FILE_SUFFIXES``)."""
    from mjx_pick.gui.grasp_input import FILE_SUFFIXES

    if Path(name).suffix.lower() not in FILE_SUFFIXES:
        return (
            f"{name}: not a grasp file (ACRONYM .h5, GraspGen .json, isaac_grasp .yaml, "
            "a CSV of poses .csv)"
        )
    if size > GRASPS_MAX_BYTES:
        return _too_large(name, size, GRASPS_MAX_BYTES)
    if size == 0:
        return f"{name}: the file is empty"
    return ""


def browser_refused(files: list[dict], refused) -> str:
    """What the page says of files the browser refused to send (QUploader's
    ``rejected``: each {name, size, reason}): each by its name and why, by the upload's
    own rule refused(name, size) -- the reason the browser gave only where the rule
    finds none."""
    said = []
    for f in files or [{}]:
        name, size = str(f.get("name") or "the file"), int(f.get("size") or 0)
        said.append(refused(name, size) or f"{name}: refused by the browser ({f.get('reason')})")
    return "; ".join(said)
