"""Flags made from the settings' declarations (``config.setting``): one per field.

A flag is named after its field (``grasp.grip_force_n`` -> ``--grip-force-n``); its help
says the field's meaning, unit, range and default, read from the declaration when help
is shown (so that parsing imports no settings module).
"""

from __future__ import annotations

import argparse
import functools
import importlib
import typing
from collections import UserString

from mjx_pick.core.config import describe_fields

# section -> (its settings dataclass, the flag of the TOML file its flags override)
SECTIONS = {
    "contact": ("mjx_pick.core.physics:ContactParams", "--contact"),
    "solver": ("mjx_pick.core.physics:SolverParams", "--solver"),
    "grasp": ("mjx_pick.core.procedure:GraspConfig", "--grasp"),
    "picks": ("mjx_pick.core.pickpoints:PickConfig", None),
}
# the settings that have a flag of their own (the others: through their section's file)
PHYSICS_FLAGS = (
    ("grasp", "grip_force_n"),
    ("contact", "pad_friction"),
    ("contact", "table_friction"),
    ("solver", "timestep_s"),
    ("grasp", "lift_height_mm"),
    ("grasp", "hold_s"),
    ("grasp", "grasp_height"),
    ("grasp", "fingertip_clearance_mm"),
)
PICK_FLAGS = (("picks", "safety_zone_mm"), ("picks", "min_coverage"), ("picks", "resolution_mm"))


def flag(name: str) -> str:
    """A field's flag: grip_force_n -> --grip-force-n."""
    return "--" + name.replace("_", "-")


@functools.cache
def section_class(section: str) -> type:
    module, _, attr = SECTIONS[section][0].partition(":")
    return getattr(importlib.import_module(module), attr)


def _field(section: str, name: str) -> dict:
    return next(f for f in describe_fields(section_class(section)) if f["name"] == name)


class _Help(UserString):
    """A flag's help text, made from the field's declaration when first read."""

    def __init__(self, section: str, name: str | None = None):
        if name is None:  # UserString's own copies (strip, ...): plain text
            self.data = section
        self.section, self.name = section, name

    @functools.cached_property
    def data(self) -> str:  # UserString's text
        f = _field(self.section, self.name)
        default = f["default"]
        default = f"{default:g}" if isinstance(default, float) else str(default)
        words = {None: "", "-": ", dimensionless"}  # a number without a unit says so
        unit = words.get(f["unit"], f", {f['unit']}")
        if f["unit"] == "-" and " | " in f["range"]:
            unit = ""  # a choice of words
        file_flag = SECTIONS[self.section][1]
        also = f", or {file_flag}'s" if file_flag else ""
        return f"{f['meaning']}{unit}; {f['range']} (default: {default}{also})"


class _Value:
    """A flag's type: text -> the field's Python type (float, int or str)."""

    def __init__(self, section: str, name: str):
        self.section, self.name = section, name

    @property
    def __name__(self) -> str:  # argparse's word for the type in its errors
        return self._type().__name__

    def _type(self) -> type:
        cls = section_class(self.section)
        hint = typing.get_type_hints(cls)[self.name]
        kinds = [t for t in typing.get_args(hint) or (hint,) if t is not type(None)]
        return kinds[0]

    def __call__(self, text: str):
        return self._type()(text)


def add_setting_flags(group, flags) -> None:
    """One flag per (section, field) of flags, into an argparse group."""
    for section, name in flags:
        group.add_argument(
            flag(name), dest=name, type=_Value(section, name), help=_Help(section, name)
        )


def given(args: argparse.Namespace, section: str) -> dict:
    """The values the user gave to the flags of one section: field -> value."""
    names = [n for s, n in (*PHYSICS_FLAGS, *PICK_FLAGS) if s == section]
    values = {n: getattr(args, n, None) for n in names}
    return {n: v for n, v in values.items() if v is not None}
