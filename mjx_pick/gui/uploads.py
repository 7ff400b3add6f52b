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
TRIALS_MAX_BYTES = 50 * 2**20  # a zip of a TRIALS.csv, its meshes and gripper TOMLs
TRIALS_MAX_UNPACKED = 500 * 2**20  # what such a zip may hold unpacked (a zip bomb is not)
TRIALS_MAX_FILES = 2000
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

    kind = "not a grasp file (ACRONYM .h5, GraspGen .json, isaac_grasp .yaml, a CSV of poses .csv)"
    return _file_refused(name, size, FILE_SUFFIXES, GRASPS_MAX_BYTES, kind)


def trials_refused(name: str, size: int) -> str:
    """Why an upload of physical trials is refused by its name or size ('' if not): a
    zip of a TRIALS.csv with the meshes and gripper TOMLs it names, beside it as the
    CSV names them."""
    kind = "not a .zip file (a zip of a TRIALS.csv with the meshes and gripper files it names)"
    return _file_refused(name, size, (".zip",), TRIALS_MAX_BYTES, kind)


def _file_refused(name: str, size: int, suffixes, most: int, kind: str) -> str:
    """Why a file is refused by its name (its suffix not one of suffixes: "NAME: kind"),
    its size (over most bytes) or its emptiness ('' if not)."""
    if Path(name).suffix.lower() not in suffixes:
        return f"{name}: {kind}"
    if size > most:
        return _too_large(name, size, most)
    if size == 0:
        return f"{name}: the file is empty"
    return ""


def store_trials(data: bytes, name: str, folder: Path, workdir: Path) -> Path:
    """An uploaded zip of physical trials, unpacked into a new folder under folder
    (``<zip name>``, ``-2``, ...: never over another upload) inside workdir; returns
    its TRIALS.csv. Every member is checked before anything is written: a path that
    leaves the folder (absolute, ``..``, a drive), a link, more than TRIALS_MAX_FILES
    files or TRIALS_MAX_UNPACKED bytes unpacked, and not exactly one TRIALS.csv (a CSV
    whose header names grasp_pose and success) are refused, naming the member. macOS's
    ``__MACOSX/`` folder (the archiver's metadata, not the user's files) is left out."""
    import io
    import stat
    import zipfile
    from pathlib import PurePosixPath

    from mjx_pick.gui.workfolder import confined

    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise ConfigError(f"{name}: cannot be read as a zip file") from None
    members, trials, total = [], [], 0
    with archive:
        for info in archive.infolist():
            path = PurePosixPath(info.filename.replace("\\", "/"))
            if info.is_dir() or (path.parts and path.parts[0] == "__MACOSX"):
                continue
            if path.is_absolute() or ".." in path.parts or ":" in info.filename:
                raise ConfigError(
                    f"{name}: {info.filename!r} would be written outside the zip's folder: "
                    "give paths relative to the TRIALS.csv"
                )
            if stat.S_ISLNK(info.external_attr >> 16):
                raise ConfigError(f"{name}: {info.filename!r} is a link: give the file itself")
            total += info.file_size
            members.append((info, path))
            if path.suffix.lower() == ".csv":
                with archive.open(info) as fh:
                    header = fh.readline(4096).decode("utf-8-sig", errors="replace")
                if {"grasp_pose", "success"} <= {c.strip() for c in header.split(",")}:
                    trials.append(path)
        if len(members) > TRIALS_MAX_FILES or total > TRIALS_MAX_UNPACKED:
            raise ConfigError(
                f"{name}: {len(members):,} files of {_megabytes(total)} unpacked: at most "
                f"{TRIALS_MAX_FILES:,} files of {_megabytes(TRIALS_MAX_UNPACKED)}"
            )
        if len(trials) != 1:
            found = ", ".join(str(t) for t in trials) or "none"
            raise ConfigError(
                f"{name}: holds {len(trials)} TRIALS.csv files ({found}): give one, a CSV "
                "whose header names object, mass_g, gripper, grasp_pose, success, trial"
            )
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(name).stem)[:60] or "trials"
        confined(folder, workdir)  # the uploads folder itself: never one a link leads out
        folder.mkdir(parents=True, exist_ok=True)
        for k in range(1, 1000):
            target = folder / (stem if k == 1 else f"{stem}-{k}")
            try:
                target.mkdir()
                break
            except FileExistsError:
                continue
        else:
            raise ConfigError(f"too many uploads named {name!r} in {folder}")
        for info, path in members:
            out = confined(target.joinpath(*path.parts), workdir)
            write_atomic(out, archive.read(info))
    return target.joinpath(*trials[0].parts)


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
