"""How the page writes numbers and names things (no web framework)."""

from __future__ import annotations

import datetime
import math

# The one frame of every pick-point the page shows or takes: the object's planar pose
# relative to the gripper's centre (the results table's x_mm, y_mm, yaw_deg)
FRAME_NAME = "gripper frame (the object's offset under the gripper)"
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


def column_label(key: str) -> str:
    """A result column's heading: its label, else the key with spaces."""
    return COLUMN_LABELS.get(key, key.replace("_", " "))


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
    return "".join("\\" + c if c in _MARKDOWN else c for c in str(text))
