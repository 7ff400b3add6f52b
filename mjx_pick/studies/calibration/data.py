"""Measured outcomes and traces: the CSV a user fills in, read and checked, and written.

Details: docs/calibration.md (studies/calibration/data.py).
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError, open_csv, write_atomic

REQUIRED = ("x_mm", "y_mm", "yaw_deg", "grip_force_n", "trials", "successes")
OPTIONAL = ("lift_time_s", "force_trace", "trace")
# what a trace may hold: column -> what it is (the residual of each is in loss.py)
TRACE_KINDS = {
    "force_n": "mean pad force, N (a force gauge in the pads)",
    "lift_mm": "the object's rise above its starting height, mm (video)",
    "rotation_deg": "the object's turn about the vertical axis since the start, deg (video)",
}


@dataclasses.dataclass(frozen=True)
class Outcomes:
    """Measured outcomes, one entry per tested pick-point ((R,) arrays).

    traces: per row None or {kind: (K, 2) array of (t_s, value)}, kind in TRACE_KINDS.
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    yaw_deg: np.ndarray
    grip_force_n: np.ndarray
    trials: np.ndarray
    successes: np.ndarray
    lift_time_s: np.ndarray  # NaN where not measured
    traces: tuple
    # what the outcomes were measured with (provenance.read_measured), or None
    measured: dict | None = None
    # the grasps tried, where they are poses (physical trials: ``validation.trial_outcomes``),
    # already checked; None: the rows' pick-points (x_mm, y_mm, yaw_deg)
    grasps: object = None

    def __len__(self) -> int:
        return len(self.x_mm)

    def take(self, index) -> Outcomes:
        index = np.atleast_1d(np.arange(len(self))[index])
        arrays = {
            f.name: getattr(self, f.name)[index]
            for f in dataclasses.fields(self)
            if isinstance(getattr(self, f.name), np.ndarray)
        }
        grasps = None if self.grasps is None else self.grasps.take(index)
        traces = tuple(self.traces[i] for i in index)
        return dataclasses.replace(self, **arrays, traces=traces, grasps=grasps)

    @property
    def fraction(self) -> np.ndarray:
        return self.successes / self.trials

    def trace_kinds(self) -> tuple[str, ...]:
        """The trace kinds measured on at least one row."""
        have = {k for t in self.traces if t for k in t}
        return tuple(k for k in TRACE_KINDS if k in have)


def make_outcomes(x_mm, y_mm, yaw_deg, grip_force_n, trials=None, successes=None) -> Outcomes:
    """Outcomes of the given pick-points with no results yet (trials 1, successes 0)."""
    x, y, yaw, f = (
        np.atleast_1d(np.asarray(a, float)) for a in (x_mm, y_mm, yaw_deg, grip_force_n)
    )
    n = len(x)
    trials = np.ones(n) if trials is None else np.asarray(trials, float)
    successes = np.zeros(n) if successes is None else np.asarray(successes, float)
    return Outcomes(x, y, yaw, f, trials, successes, np.full(n, np.nan), tuple([None] * n))


def example_outcomes() -> list[str]:
    """Names of the shipped example outcome files (assets/outcomes/*.csv)."""
    from importlib import resources

    folder = resources.files("mjx_pick.assets") / "outcomes"
    return sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".csv"))


def read_outcomes(path: str | Path) -> Outcomes:
    """Read and check a measured-outcomes CSV (see the module docstring); a shipped
    example may be named without a path (e.g. "block_1kg_rg2")."""
    path = Path(path)
    if not path.is_file() and str(path) in example_outcomes():
        from importlib import resources

        with resources.as_file(
            resources.files("mjx_pick.assets") / "outcomes" / f"{path}.csv"
        ) as p:
            return read_outcomes(p)
    if not path.is_file():
        raise ConfigError(
            f"outcomes file {str(path)!r} does not exist (shipped examples: "
            f"{', '.join(example_outcomes())})"
        )
    with open_csv(path, "outcomes") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise ConfigError(
                f"outcomes file {path.name}: missing column(s) {', '.join(missing)}; "
                f"found {header}; required: {', '.join(REQUIRED)}"
            )
        unknown = [c for c in header if c not in REQUIRED + OPTIONAL]
        if unknown:
            raise ConfigError(
                f"outcomes file {path.name}: unknown column(s) {', '.join(unknown)}; "
                f"allowed: {', '.join(REQUIRED + OPTIONAL)}"
            )
        rows = list(reader)
    if not rows:
        raise ConfigError(f"outcomes file {path.name} has no rows")
    from mjx_pick.studies.calibration.provenance import read_measured

    measured = read_measured(path)  # the record beside it: mass, gripper, procedure
    return dataclasses.replace(outcomes_from_rows(rows, path), measured=measured)


def outcomes_from_rows(
    rows: list[dict], path: Path, lines: list[int] | None = None, label: str = "outcomes file"
) -> Outcomes:
    """Outcomes of CSV rows (dicts of cell text, as ``csv.DictReader`` gives them) of the
    file `path` (trace files are found beside it), with every check of
    :func:`read_outcomes`; lines: each row's line in the file, for the errors (default:
    2, 3, ...); label: what the errors call the file. Columns other than REQUIRED and
    OPTIONAL are not read."""
    lines = list(range(2, len(rows) + 2)) if lines is None else list(lines)
    cols = {c: [] for c in REQUIRED}
    lift, traces = [], []
    for line, row in zip(lines, rows, strict=True):
        where = f"{label} {path.name}, row {line}"
        for c in REQUIRED:
            try:
                v = float(row[c])
            except (TypeError, ValueError):
                raise ConfigError(f"{where}, column {c}: {row[c]!r} is not a number") from None
            if not math.isfinite(v):
                raise ConfigError(f"{where}, column {c}: {v} must be finite")
            cols[c].append(v)
        t, s = cols["trials"][-1], cols["successes"][-1]
        if t < 1 or t != int(t):
            raise ConfigError(f"{where}, column trials: {t:g} must be a whole number >= 1")
        if s < 0 or s != int(s) or s > t:
            raise ConfigError(
                f"{where}, column successes: {s:g} must be a whole number in 0..trials ({t:g})"
            )
        if cols["grip_force_n"][-1] <= 0:
            raise ConfigError(f"{where}, column grip_force_n: must be > 0")
        text = (row.get("lift_time_s") or "").strip()
        try:
            lift.append(float(text) if text else math.nan)
        except ValueError:
            raise ConfigError(f"{where}, column lift_time_s: {text!r} is not a number") from None
        row_traces = {}
        force = (row.get("force_trace") or "").strip()
        if force:
            row_traces.update(
                read_trace(path.parent / force, f"{where}, column force_trace", ("force_n",))
            )
        both = (row.get("trace") or "").strip()
        if both:
            got = read_trace(path.parent / both, f"{where}, column trace", tuple(TRACE_KINDS))
            twice = sorted(set(got) & set(row_traces))
            if twice:
                raise ConfigError(f"{where}: {', '.join(twice)} given in force_trace and trace")
            row_traces.update(got)
        traces.append(row_traces or None)
    return Outcomes(
        **{c: np.asarray(cols[c], float) for c in REQUIRED},
        lift_time_s=np.asarray(lift, float),
        traces=tuple(traces),
    )


def read_trace(path: Path, where: str, allowed: tuple[str, ...]) -> dict[str, np.ndarray]:
    """A trace CSV: t_s plus columns of `allowed`; {kind: (K, 2) (t_s, value)}."""
    if not path.is_file():
        raise ConfigError(f"{where}: {str(path)!r} does not exist")
    with open_csv(path, f"{where}: trace") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        rows = list(reader)
    kinds = [h for h in header if h != "t_s"]
    unknown = [h for h in kinds if h not in allowed]
    if "t_s" not in header or not kinds or unknown:
        raise ConfigError(
            f"{where}: {path.name} needs a column t_s and at least one of "
            f"{', '.join(allowed)}; found {header}"
        )
    out = {}
    try:
        t = np.array([float(r["t_s"]) for r in rows])
    except (TypeError, ValueError):
        raise ConfigError(
            f"{where}: {path.name}, column t_s: every time must be a number"
        ) from None
    if len(t) < 2 or not np.isfinite(t).all() or not np.all(np.diff(t) > 0):
        raise ConfigError(f"{where}: {path.name}: needs 2+ rows, times must increase")
    for k in kinds:
        vals = []
        for i, r in enumerate(rows, start=2):
            text = (r.get(k) or "").strip()
            try:
                vals.append(float(text) if text else math.nan)
            except ValueError:
                raise ConfigError(
                    f"{where}: {path.name}, row {i}, column {k}: {text!r} is not a number"
                ) from None
        v = np.asarray(vals)
        if np.isinf(v).any():
            raise ConfigError(f"{where}: {path.name}, column {k}: values must be finite")
        keep = np.isfinite(v)
        if keep.sum() < 2:
            raise ConfigError(f"{where}: {path.name}, column {k}: needs 2+ measured values")
        out[k] = np.stack([t[keep], v[keep]], axis=1)
    return out


def write_outcomes(path: str | Path, outcomes: Outcomes) -> None:
    """Write outcomes as CSV; a row's traces go beside it as <stem>_trace_<row>.csv."""
    path = Path(path)
    lines = [",".join(REQUIRED + ("lift_time_s", "trace"))]
    for i in range(len(outcomes)):
        name = ""
        tr = outcomes.traces[i]
        if tr:
            name = f"{path.stem}_trace_{i}.csv"
            kinds = [k for k in TRACE_KINDS if k in tr]
            t = np.unique(np.concatenate([tr[k][:, 0] for k in kinds]))
            cols = []
            for k in kinds:
                col = np.full(len(t), np.nan)
                col[np.searchsorted(t, tr[k][:, 0])] = tr[k][:, 1]
                cols.append(col)
            body = "".join(
                f"{ti:.5f},"
                + ",".join("" if np.isnan(c[j]) else f"{c[j]:.5g}" for c in cols)
                + "\n"
                for j, ti in enumerate(t)
            )
            write_atomic(path.parent / name, "t_s," + ",".join(kinds) + "\n" + body)
        lift = outcomes.lift_time_s[i]
        lines.append(
            f"{outcomes.x_mm[i]:.4f},{outcomes.y_mm[i]:.4f},{outcomes.yaw_deg[i]:.4f},"
            f"{outcomes.grip_force_n[i]:.6g},{int(outcomes.trials[i])},"
            f"{int(outcomes.successes[i])},{'' if math.isnan(lift) else f'{lift:.4f}'},{name}"
        )
    write_atomic(path, "\n".join(lines) + "\n")
