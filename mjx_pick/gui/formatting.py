"""How the page writes numbers and names things (no web framework)."""

from __future__ import annotations

import datetime
import math
import re
import sys
import sysconfig
import traceback
from pathlib import Path

# The one frame of every pick-point the page shows or takes: the object's planar pose
# relative to the gripper's centre (the results table's x_mm, y_mm, yaw_deg)
FRAME_NAME = "gripper frame (the object's offset under the gripper)"
# what the page's pick-point maps draw: the same frame, said beside each map
MAP_HELP = (
    "Map and values in one frame, the gripper frame: the gripper's centre at 0, x along "
    "the fingers' closing direction, y across it, yaw counter-clockwise seen from above "
    "(the arrows in the corner). Each mark is where the object's centre (the + of tab 1) "
    "lies under the gripper, its tick the object's own x axis; the grey blocks are the "
    "fingers fully open. A click on a pick-point draws it whole: the part at its pose, "
    "the fingers at its opening."
)
PICK_LABELS = {
    "x_mm": "object x under gripper (mm)",
    "y_mm": "object y under gripper (mm)",
    "yaw_deg": "object yaw under gripper (deg)",
}
# the studies' result columns in the user's words (the JSON keys stay in the files)
COLUMN_LABELS = {
    **PICK_LABELS,
    "pick_id": "pick",
    "success_rate": "success rate",
    "success_ci": "success rate, 95 % interval",
    "score_mean": "mean score",
    "score_ci": "mean score, 95 % interval",
    "feasible": "feasible pick-points",
    "p_vs_best": "chance the difference to the best is luck (p)",
    "robust_p": "success probability under the errors",
    "robust_ci_low": "its 95 % lower bound",
    "landed": "draws with a finger on the part",
    "n": "pick-points",
    "successes": "successes",
}


def compensation_text(mm: float) -> str:
    """A pick's height compensation in the page's words: the one meaning the word has
    in the results, the exports and docs/formats.md (never the fingertip height)."""
    from mjx_pick.core.metrics import COLUMNS

    return f"height compensation: {mm:.1f} mm ({COLUMNS['height_compensation_mm'][1]})"


def column_label(key: str) -> str:
    """A result column's heading: its label, else the key in words (:func:`key_words`)."""
    return COLUMN_LABELS.get(key) or key_words(key)


# a key's unit suffix (the project's naming convention: the unit in the name) in words,
# longest first
_UNITS = (
    ("_n_per_mm", "N/mm"),
    ("_ns_per_mm", "N s/mm"),
    ("_mm_s_per_n", "mm/s per N"),
    ("_kg_m3", "kg/m³"),
    ("_mm_s", "mm/s"),
    ("_mm2", "mm²"),
    ("_mm", "mm"),
    ("_deg", "deg"),
    ("_um", "µm"),
    ("_kg", "kg"),
    ("_g", "g"),
    ("_n", "N"),
    ("_s", "s"),
)
# keys that read wrong with their underscores as spaces
_KEY_WORDS = {
    "n": "pick-points",
    "n_traces": "traced best and worst",
    "chunk_size": "pick-points per saved chunk",
    "batch_size": "batch size",
    "step_check": "check each label",
    "stability_um": "check each label (the part moved, µm)",
    "model": "the simulated scene",
    "source": "the pick-points",
    "min_force": "minimum force search",
    "outline_wkt": "outline",
    "area_mm2": "outline area (mm²)",
    "height_mm": "thickness (mm)",
    "pick_height_mm": "fingertip height (mm)",
    "n_holes": "holes",
    "n_collision_pieces": "collision pieces",
    "bounds_mm": "extent (mm)",
    "max_n": "most pick-points",
    "min_score": "score of a good pick-point",
    "until": "good pick-points wanted",
}


def key_words(key: str) -> str:
    """A key of the program (a result column, a recorded setting, a JSON field) in the
    page's words: its own words where it has them, else its name with spaces and its
    unit in brackets (grip_force_n -> "grip force (N)"); a section before a dot said
    first ("object.mass_g" -> "object mass (g)")."""
    section, _, name = key.rpartition(".")
    if name in _KEY_WORDS:
        words = _KEY_WORDS[name]
    else:
        suffix, unit = next(((x, u) for x, u in _UNITS if name.endswith(x)), ("", ""))
        stem = name[: len(name) - len(suffix)] or name
        words = stem.replace("_", " ") + (f" ({unit})" if stem != name else "")
    if section:
        words = f"{section.rsplit('.', 1)[-1].split('[', 1)[0]} {words}"
    return words


def outcome_words(label: str) -> str:
    """A pick's outcome (the results' ``failure`` label, force_not_reached) in words."""
    return label.replace("_", " ")


def stamp() -> str:
    """The time now, for default run folder names (``evaluate-20260101-120000``)."""
    return datetime.datetime.now().strftime("%Y%m%d-%H%M%S")


def fmt(v, digits: int = 3) -> str:
    """A number as the page shows it: fixed digits, NaN by name, anything else as str."""
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, float):
        return "NaN" if math.isnan(v) else f"{v:.{digits}f}"
    return str(v)


def fmt_cell(v) -> str:
    """A table cell: a number, or a list of numbers (an interval) in brackets."""
    if isinstance(v, list | tuple):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    return fmt(v)


_MARKDOWN = set("\\`*_{}[]()#+-.!|<>~")


def md_text(text: str) -> str:
    """Plain text (a file name, a library's message) for a markdown element: every
    character markdown reads as markup escaped, so that contact.pad_friction keeps its
    underscore and a path its stars."""
    return "".join("\\" + c if c in _MARKDOWN else c for c in page_text(text))


def _install_roots() -> tuple[str, ...]:
    """Folders of Python's and this package's installation: a path inside them names
    the software's files, never the user's."""
    import mjx_pick

    roots = {str(Path(mjx_pick.__file__).resolve().parent)}
    roots |= {sys.prefix, sys.base_prefix, sys.exec_prefix}
    for key in ("stdlib", "platstdlib", "purelib", "platlib"):
        path = sysconfig.get_paths().get(key)
        if path:
            roots.add(path)
    return tuple(sorted({r.rstrip("/") for r in roots if r and r != "/"}, key=len, reverse=True))


_ROOTS = _install_roots()
# an absolute path as messages write it: up to a quote, a space, a colon or a bracket
_PATH = re.compile(r"(?<![\w.])/[^\s'\"<>|;:,()\[\]]+")


def page_text(text: str) -> str:
    """A message for the page without the paths of the software's own files: a path
    into Python's or this package's installation (site-packages, a shipped asset, a
    library's source) becomes its file name. The user's own paths stay."""

    def short(m: re.Match) -> str:
        path = m.group(0).rstrip(".")  # a sentence's full stop is no part of it
        rest = m.group(0)[len(path) :]
        hidden = any(path == r or path.startswith(r + "/") for r in _ROOTS)
        hidden = hidden or "/site-packages/" in path or "/dist-packages/" in path
        return (Path(path).name if hidden else path) + rest

    return _PATH.sub(short, str(text))


def raised_in(err: BaseException) -> str:
    """The library an exception came from (its innermost frame's package): "trimesh",
    "mujoco", "mjx_pick" ..., or "Python" for the standard library."""
    frames = traceback.extract_tb(err.__traceback__)
    return library_of(frames[-1].filename) if frames else "Python"


def library_of(filename: str) -> str:
    """The package a source file belongs to, from its path."""
    parts = Path(filename).parts
    for marker in ("site-packages", "dist-packages"):
        if marker in parts and parts.index(marker) + 1 < len(parts):
            return parts[parts.index(marker) + 1].removesuffix(".py")
    if "mjx_pick" in parts:
        return "mjx_pick"
    return "Python"


def unexpected_text(what: str, library: str, kind: str, log: str) -> str:
    """The page's words for an error no input check foresaw: what failed, in which
    library, and where the full error is -- never a traceback or a library's own text."""
    inside = "mjx-pick itself" if library == "mjx_pick" else library
    return (
        f"{what} failed on an unexpected error inside {inside} ({kind}) that the input "
        f"checks did not catch; the full error is in {log}"
    )
