"""Configuration plumbing shared by every stage: validation, TOML/JSON round trips.

Every user-facing setting lives in a frozen dataclass whose defaults are the paper's
values. A value out of range raises :class:`ConfigError`, which names the field, the
value and what is allowed, at construction time, before any simulation starts.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import re
import tempfile
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from mjx_pick.core.escape import toml_string

T = TypeVar("T")


class ConfigError(ValueError):
    """A user input (a setting, a file, a value) is invalid; the message says why."""


class PlausibilityWarning(UserWarning):
    """A user input is allowed but implausible (a density no solid has, a time step
    above the converged one), or was adapted to fit (a raster coarsened to stay within
    memory); the message gives the numbers and what to check."""


def check_range(
    owner: str,
    field: str,
    value: float,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
) -> None:
    """Raise ConfigError unless value is a finite number with lo <= value <= hi
    (strict where *_open), and a whole number where integer."""
    name = f"{owner}.{field}" if owner else field
    if isinstance(value, bool) or not isinstance(value, (int, float, *_np_number())):
        raise ConfigError(f"{name} = {value!r} must be a number")
    if not math.isfinite(value):
        raise ConfigError(f"{name} = {value!r} must be a finite number")
    if integer and value != int(value):
        raise ConfigError(f"{name} = {value!r} must be a whole number")
    bad = (lo is not None and (value <= lo if lo_open else value < lo)) or (
        hi is not None and (value >= hi if hi_open else value > hi)
    )
    if bad:
        lo_s = "" if lo is None else f"{bound_text(lo)} {'<' if lo_open else '<='} "
        hi_s = "" if hi is None else f" {'<' if hi_open else '<='} {bound_text(hi)}"
        raise ConfigError(f"{name} = {value!r} is out of range: allowed {lo_s}{field}{hi_s}")


def bound_text(b: float) -> str:
    """A bound as a person reads it: whole numbers in full (4294967295, not 4.29e+09)."""
    if isinstance(b, int | float) and float(b).is_integer() and abs(b) < 1e12:
        return str(int(b))
    return f"{b:g}"


def _np_number() -> tuple:
    """numpy's scalar number types where numpy is loaded (a value read from a table)."""
    import sys

    np = sys.modules.get("numpy")
    return (np.integer, np.floating) if np is not None else ()


@dataclasses.dataclass(frozen=True)
class Number:
    """What one numeric input may be: the one rule a settings field (:func:`setting`),
    a run option or a study parameter declares, and the CLI, the GUI and the library
    check alike -- finite, within [lo, hi] (strict where *_open), whole where integer.

    unit: its unit ("mm", "N", ...; "-" for a plain number); doc: one line, its meaning.
    """

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    unit: str = "-"
    doc: str = ""

    def check(self, name: str, value: Any, where: str = "") -> int | float:
        """value, checked (ConfigError naming name, value and what is allowed, after
        where: "picks.csv, line 3: "); an int where integer."""
        try:
            check_range(
                "",
                name,
                value,
                self.lo,
                self.hi,
                lo_open=self.lo_open,
                hi_open=self.hi_open,
                integer=self.integer,
            )
        except ConfigError as err:
            raise ConfigError(f"{where}{err}") from None
        return int(value) if self.integer else float(value)

    def parse(self, name: str, text: str | float, where: str = "") -> int | float:
        """The number a user typed (a CLI flag, a form field, a CSV cell), checked."""
        if isinstance(text, str):
            raw = text.strip()
            try:
                value: Any = int(raw) if self.integer and _INT.match(raw) else float(raw)
            except ValueError:
                kind = "a whole number" if self.integer else "a number"
                raise ConfigError(f"{where}{name} = {text!r} is not {kind}") from None
        else:
            value = text
        return self.check(name, value, where)

    def text(self, name: str = "x") -> str:
        """The allowed values in words: "0 <= n <= 100 (a whole number)"."""
        words = range_text((self.lo, self.hi, self.lo_open, self.hi_open)).replace("x", name, 1)
        if words == "any":
            words = "any finite number"
        return words + (" (a whole number)" if self.integer else "")


_INT = re.compile(r"^[+-]?\d+$")


Bound = float | str | None  # a number, no bound, or another field: "name" / "name + 360"


def setting(
    default: Any,
    unit: str,
    doc: str,
    *,
    lo: Bound = None,
    hi: Bound = None,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple | None = None,
    integer: bool | None = None,
) -> Any:
    """A settings-dataclass field that says what it is: its unit, its meaning and the
    range it must lie in. The one definition: :func:`check_fields` (called by the
    dataclass's ``__post_init__``) enforces the range, and ``mjx-pick params``
    (:func:`describe_fields`) shows the same facts.

    Args:
      unit: the field's unit ("mm", "N", "s", "mm/s", ...; "-" for a plain number).
      doc: one line, what the field means.
      lo, hi: the allowed range (inclusive; strict where lo_open / hi_open): a number,
        None (unbounded), or another field of the same settings by name, with an
        optional offset ("yaw_min_deg + 360"), read from the instance being checked.
        A field whose value is None (where None is allowed) is not checked.
      choices: the values a text field may take (instead of a range).
      integer: the value must be a whole number (default: when the default is an int).
    """
    if integer is None:
        integer = isinstance(default, int) and not isinstance(default, bool)
    rng = None if choices else (lo, hi, lo_open, hi_open)
    meta = {"unit": unit, "doc": doc, "range": rng, "choices": choices, "integer": integer}
    return dataclasses.field(default=default, metadata=meta)


def field_number(cls: type, name: str) -> Number:
    """The :class:`Number` rule of a settings field declared with :func:`setting` (a
    bound that names another field is left open: it is checked with the instance)."""
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    if f.metadata.get("range") is None:
        raise KeyError(f"{cls.__name__}.{name} is not declared with setting()")
    lo, hi, lo_open, hi_open = f.metadata["range"]
    return Number(
        lo if not isinstance(lo, str) else None,
        hi if not isinstance(hi, str) else None,
        lo_open,
        hi_open,
        bool(f.metadata.get("integer")),
        f.metadata["unit"],
        f.metadata["doc"],
    )


_BOUND = re.compile(r"^\s*([A-Za-z_]\w*)\s*(?:([+-])\s*([0-9.eE+-]+))?\s*$")


def _bound(obj: Any, bound: Bound) -> float | None:
    if bound is None or isinstance(bound, int | float):
        return bound
    m = _BOUND.match(bound)
    if m is None:
        raise ValueError(f"bad bound {bound!r}: write a number, 'field' or 'field + number'")
    value = getattr(obj, m[1])
    offset = float(m[3]) if m[3] else 0.0
    return value + offset if m[2] != "-" else value - offset


def check_fields(obj: Any, owner: str) -> None:
    """Check every field of a settings dataclass declared with :func:`setting` against
    its range (``check_range``: the first bad value is a ConfigError naming it): in the
    order of the fields, those bounded by another field last."""
    for f in dataclasses.fields(obj):
        if f.metadata.get("choices"):
            check_choice(owner, f.name, getattr(obj, f.name), f.metadata["choices"])
    declared = [f for f in dataclasses.fields(obj) if f.metadata.get("range") is not None]
    # fields bounded by numbers first: a bound read from another field is then valid
    relative = [f for f in declared if any(isinstance(b, str) for b in f.metadata["range"][:2])]
    for f in [f for f in declared if f not in relative] + relative:
        value = getattr(obj, f.name)
        if value is not None:
            _check_declared(obj, f, value, owner)


def check_field(obj: Any, name: str, value: Any, owner: str) -> None:
    """value checked against field `name` of settings dataclass obj as declared
    (:func:`setting`), a bound that names another field read from obj: what
    ``dataclasses.replace(obj, name=value)`` would refuse for the field itself (a search
    bound, a sweep's values, checked before any variant is drawn)."""
    f = next(f for f in dataclasses.fields(obj) if f.name == name)
    if f.metadata.get("range") is not None:
        _check_declared(obj, f, value, owner)


def _check_declared(obj: Any, f: dataclasses.Field, value: Any, owner: str) -> None:
    """value against field f's declared range (a bound naming another field read from
    obj) and its integer rule: ``check_range``."""
    lo, hi, lo_open, hi_open = f.metadata["range"]
    lo, hi = _bound(obj, lo), _bound(obj, hi)
    integer = bool(f.metadata.get("integer"))
    check_range(owner, f.name, value, lo, hi, lo_open=lo_open, hi_open=hi_open, integer=integer)


def range_text(rng: tuple | None) -> str:
    """A field's allowed range in words: "0 < x <= 5", "x >= 1", "any"."""
    if rng is None:
        return "any"
    lo, hi, lo_open, hi_open = rng
    fmt = lambda b: bound_text(b) if isinstance(b, int | float) else str(b)  # noqa: E731
    if lo is None and hi is None:
        return "any"
    if hi is None:
        return f"x {'>' if lo_open else '>='} {fmt(lo)}"
    if lo is None:
        return f"x {'<' if hi_open else '<='} {fmt(hi)}"
    return f"{fmt(lo)} {'<' if lo_open else '<='} x {'<' if hi_open else '<='} {fmt(hi)}"


def describe_fields(cls: type) -> list[dict]:
    """Each field of a settings dataclass: name, unit, meaning, default and range text
    (from its :func:`setting` declaration; a field declared without one gives unit and
    meaning None)."""
    out = []
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = None
        out.append(
            {
                "name": f.name,
                "unit": f.metadata.get("unit"),
                "meaning": f.metadata.get("doc"),
                "default": default,
                "range": (
                    " | ".join(f.metadata["choices"])
                    if f.metadata.get("choices")
                    else range_text(f.metadata.get("range"))
                ),
            }
        )
    return out


NAME_RULE = (
    "1-100 characters, without '/', '\\', control characters, a leading '.' or spaces at either end"
)


def check_name(owner: str, name: Any) -> None:
    """Raise ConfigError unless name is a name that results, file names and reports may
    carry as it is: text of 1-100 characters without a path separator, a control
    character or a leading dot (any other Unicode, an emoji too, is fine)."""
    ok = (
        isinstance(name, str)
        and 0 < len(name) <= 100
        and not name.startswith(".")
        and not any(c in "/\\" or ord(c) < 32 or ord(c) == 127 for c in name)
        and name.strip() == name
    )
    if not ok or any(0xD800 <= ord(c) <= 0xDFFF for c in name):
        raise ConfigError(f"{owner}.name = {name!r} is not allowed: {NAME_RULE}")


def check_choice(owner: str, field: str, value: Any, choices: tuple) -> None:
    """Raise ConfigError unless value is one of choices."""
    if value not in choices:
        raise ConfigError(
            f"{owner}.{field} = {value!r} is not allowed: choose one of "
            + ", ".join(repr(c) for c in choices)
        )


def from_mapping(cls: type[T], data: Mapping[str, Any], *, where: str = "") -> T:
    """Build dataclass cls from a mapping, rejecting unknown keys by name.

    Nested dataclass fields accept nested mappings. Lists become tuples so the result
    stays hashable (frozen dataclasses are used as static jit arguments).
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    label = where or cls.__name__
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"{label}: unknown setting(s) {', '.join(unknown)}; known: {', '.join(sorted(fields))}"
        )
    kwargs = {}
    for key, value in data.items():
        ftype = fields[key].type
        sub = _dataclass_type(cls, key, ftype)
        if sub is not None and isinstance(value, Mapping):
            value = from_mapping(sub, value, where=f"{label}.{key}")
        elif isinstance(value, list):
            value = tuple(value)
        _check_kind(f"{label}.{key}", value, fields[key])
        kwargs[key] = value
    try:
        return cls(**kwargs)
    except TypeError as err:  # a value of a kind the checks above do not know
        raise ConfigError(f"{label}: {err}") from err


def _check_kind(name: str, value: Any, field: dataclasses.Field) -> None:
    """Reject a value whose kind (list, text, number, true/false) differs from the
    field's default's -- before the dataclass's own range checks meet it."""
    if field.default is not dataclasses.MISSING:
        default = field.default
    elif field.default_factory is not dataclasses.MISSING:
        default = field.default_factory()
    else:
        return
    if default is None or dataclasses.is_dataclass(default):
        return
    kinds = (
        (bool, "true or false"),
        (tuple, "a list"),
        (str, "text"),
        (int | float, "a number"),
    )
    for kind, words in kinds:
        if isinstance(default, kind):
            ok = isinstance(value, kind) and (kind is bool or not isinstance(value, bool))
            if not ok:
                raise ConfigError(f"{name} = {value!r} must be {words}")
            return


def _dataclass_type(cls: type, key: str, ftype: Any) -> type | None:
    hints = getattr(cls, "__annotations__", {})
    resolved = hints.get(key, ftype)
    if isinstance(resolved, str):
        import typing

        try:
            resolved = typing.get_type_hints(cls)[key]
        except Exception:  # noqa: BLE001 - an unresolvable hint just means "not nested"
            return None
    return resolved if dataclasses.is_dataclass(resolved) else None


def read_text(path: str | os.PathLike, what: str) -> str:
    """The text of a file a user gives (a settings or gripper TOML, a CSV, an outcomes
    record, a URDF): the one reader of them all. UTF-8, with or without the byte-order
    mark Excel and Notepad write; what names the file's kind ("ContactParams", "picks
    CSV") in the ConfigError of a file that is missing, unreadable or not UTF-8 text --
    the last naming the line and the bytes, since a Latin-1 editor's 'f\xfcr' in a
    comment looks fine to the person who typed it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} file {str(path)!r} does not exist")
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ConfigError(f"{what} file {str(path)!r} cannot be read: {err.strerror}") from err
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        bad = data[err.start : err.end]
        shown = " ".join(f"0x{b:02x}" for b in bad)
        raise ConfigError(
            f"{what} file {str(path)!r} is not UTF-8 text: line {line} holds the "
            f"byte{'s' if len(bad) > 1 else ''} {shown} (saved as Latin-1 or another legacy "
            "encoding?); save it as UTF-8"
        ) from None


def read_toml(path: str | os.PathLike, what: str) -> dict:
    """A TOML file's tables and keys (read by :func:`read_text`); what names the file's
    kind in the error of a file that is missing, not UTF-8 or not TOML."""
    try:
        return tomllib.loads(read_text(path, what))
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{str(path)!r} is not valid TOML: {err}") from err


def load_toml(cls: type[T], path: str | os.PathLike, *, table: str | None = None) -> T:
    """Load dataclass cls from a TOML file (optionally from one [table] of it)."""
    data = read_toml(path, cls.__name__)
    if table is not None:
        data = data.get(table, {})
    return from_mapping(cls, data, where=f"{Path(path).name}")


def open_csv(path: str | os.PathLike, what: str = "CSV") -> io.StringIO:
    """A user's CSV file for csv.DictReader (``with open_csv(p) as fh: ...``), read by
    :func:`read_text`: UTF-8, an Excel byte-order mark accepted, anything else a
    ConfigError naming the file and the line."""
    return io.StringIO(read_text(path, what), newline="")


def to_dict(obj: Any) -> Any:
    """Dataclass (possibly nested) to plain JSON-able Python values."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple | list):
        return [to_dict(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalar
        return obj.item()
    return obj


def to_toml(obj: Any) -> str:
    """Flat or one-level-nested dataclass to TOML text (the subset this project writes)."""
    data = to_dict(obj)
    lines, tables = [], []
    for key, value in data.items():
        if value is None:
            continue  # TOML has no null: an absent key means "the default"
        if isinstance(value, dict):
            tables.append((key, value))
        else:
            lines.append(f"{key} = {toml_value(value)}")
    for name, table in tables:
        lines.append(f"\n[{name}]")
        lines.extend(f"{k} = {toml_value(v)}" for k, v in table.items() if v is not None)
    return "\n".join(lines) + "\n"


def toml_value(value: Any) -> str:
    """A value as TOML (the subset this project writes: booleans, numbers, strings through
    ``escape.toml_string``, lists of them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if value is None:
        raise ConfigError("TOML cannot store None; leave the key out instead")
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


# Called with each path write_atomic is about to write, before any byte of it: how an
# output folder records every file its run writes (``outputs.rundir``: the only files it
# will ever remove), without this module knowing of output folders.
_WRITE_OBSERVERS: list[Callable[[Path], None]] = []


def observe_writes(observer: Callable[[Path], None]) -> None:
    """Call observer(path) before each :func:`write_atomic` (once per observer)."""
    if observer not in _WRITE_OBSERVERS:
        _WRITE_OBSERVERS.append(observer)


def write_atomic(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write a file so that readers see the old or the new content, never a partial one.
    An OSError names the file (a disk that fills raises one without a name)."""
    path = Path(path)
    for observe in _WRITE_OBSERVERS:
        observe(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        payload = data.encode() if isinstance(data, str) else data
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException as err:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        if isinstance(err, OSError) and err.filename is None:
            err.filename = str(path)
        raise
    return path


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """Atomically write obj (dataclasses allowed) as indented JSON."""
    return write_atomic(path, json.dumps(to_dict(obj), indent=2, sort_keys=False) + "\n")


def write_parquet(path: str | os.PathLike, table) -> Path:
    """Atomically write a pyarrow Table as Parquet."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return write_atomic(path, sink.getvalue().to_pybytes())
