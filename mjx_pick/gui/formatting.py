"""How the page writes numbers and names things (no web framework)."""

from __future__ import annotations

import datetime
import math


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
