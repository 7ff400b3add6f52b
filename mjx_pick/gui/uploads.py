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


def object_refused() -> str:
    """What the page says when the browser refuses an object file (type or size)."""
    return (
        "file refused: upload an image ("
        + ", ".join(IMAGE_SUFFIXES)
        + f", up to {IMAGE_MAX_BYTES // 2**20} MB) or a mesh ("
        + ", ".join(MESH_SUFFIXES)
        + f", up to {MESH_MAX_BYTES // 2**20} MB)"
    )


def check_upload(name: str, size: int, data: bytes | None = None) -> str:
    """Why an uploaded object file is refused ('' when it is accepted)."""
    suffix = Path(name).suffix.lower()
    if suffix not in UPLOAD_TYPES:
        return (
            f"{name}: not an image ({', '.join(IMAGE_SUFFIXES)}) or a mesh "
            f"({', '.join(MESH_SUFFIXES)})"
        )
    limit = IMAGE_MAX_BYTES if suffix in IMAGE_SUFFIXES else MESH_MAX_BYTES
    if size > limit:
        return f"{name}: {size / 2**20:.1f} MB is too large (at most {limit // 2**20} MB)"
    if size == 0:
        return f"{name}: the file is empty"
    if data is not None and suffix in IMAGE_SUFFIXES:
        import cv2

        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            return f"{name}: cannot be read as an image (is it really a {suffix[1:].upper()}?)"
    return ""


def check_toml_upload(name: str, data: bytes) -> str:
    """Why an uploaded gripper TOML is refused before it is parsed ('' when accepted)."""
    if not name.lower().endswith(".toml"):
        return f"{name}: not a .toml file"
    if len(data) > TOML_MAX_BYTES:
        return f"{name}: larger than {TOML_MAX_BYTES // 2**10} KB"
    return ""


def check_outcomes_upload(name: str, data: bytes) -> str:
    """Why an uploaded outcomes CSV is refused before it is read ('' when accepted)."""
    if not name.lower().endswith(".csv") or len(data) > OUTCOMES_MAX_BYTES:
        return f"{name}: not a .csv file of at most {OUTCOMES_MAX_BYTES // 2**20} MB"
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return f"{name}: not a UTF-8 text file"
    return ""
