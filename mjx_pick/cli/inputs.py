"""Command-line options -> the library's objects (object, gripper, settings, ranges).

Each converter names the option and the value it refuses (``ConfigError``)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from mjx_pick.cli import setting_flags
from mjx_pick.core.config import ConfigError, from_mapping, load_toml, read_toml
from mjx_pick.engine import registry


def each_checked(*makers):
    """Call every maker; the results, or ONE ConfigError listing every problem found (a
    user fixes all of them at once instead of one per run)."""
    values, problems = [], []
    for make in makers:
        try:
            values.append(make())
        except ConfigError as err:
            problems += getattr(err, "problems", [str(err)])  # a nested list: flattened
            values.append(None)
    raise_problems(problems)
    return values


def raise_problems(problems: list[str]) -> None:
    """ONE ConfigError listing every problem (its ``problems``); nothing when none."""
    if len(problems) == 1:
        raise ConfigError(problems[0])
    if problems:
        err = ConfigError(f"{len(problems)} problems:\n" + "\n".join(f"  - {p}" for p in problems))
        err.problems = problems
        raise err


def objects(args):
    """(object, gripper), both checked before either error is reported."""
    from mjx_pick.core.gripper import load_gripper

    obj, gripper = each_checked(
        lambda: object_of(args),
        lambda: load_gripper(args.gripper_file or args.gripper or DEFAULT_GRIPPER),
    )
    return obj, gripper


DEFAULT_GRIPPER = "robotiq-2f85"
# the options that set a gripper, physics or procedure setting, and a pick configuration's
SETTINGS_FLAGS = (
    "gripper",
    "gripper_file",
    *(s for s, (_, file_flag) in setting_flags.SECTIONS.items() if file_flag),
    *(name for _, name in setting_flags.PHYSICS_FLAGS),
)
PICK_FLAGS = tuple(name for _, name in setting_flags.PICK_FLAGS)


def given(args, names) -> bool:
    """Whether the user set any of these options (argparse leaves the others None)."""
    return any(getattr(args, n, None) is not None for n in names)


def inputs_of(args):
    """(object, gripper, contact, solver, grasp, pick config): every one checked, every
    problem reported together. A procedure value set by neither a flag nor --grasp
    (the grip force, the closing speed) is fitted into the gripper's range
    (``GraspConfig.fitted_to``), with a note on stderr."""
    from mjx_pick.core.procedure import check_clearance

    both, four = each_checked(lambda: objects(args), lambda: settings(args))
    contact, solver, (grasp, given), picks = four
    check_clearance(both[0], grasp)  # every study: before any work
    grasp, note = grasp.fitted_to(both[1], keep=given)
    if note:
        print(f"mjx-pick: note: {note}", file=sys.stderr)
    return (*both, contact, solver, grasp, picks)


# the object options of one part that a set of parts passes to each (``object_sets``):
# given, every part takes them; one its mesh does not use is refused by load_object
SET_OBJECT_OPTIONS = (
    "px_per_mm",
    "thickness_mm",
    "pick_height_mm",
    "simplify_mm",
    "material",
    "largest_body",
    "repair_volume_pct",
    "repair_com_mm",
    "repair_bounds_mm",
)


def set_object_options(args) -> dict:
    """The object options given on the command line for every part of a set (none
    given: {}, a set's key as before)."""
    given = {name: getattr(args, name, None) for name in SET_OBJECT_OPTIONS}
    return {k: v for k, v in given.items() if v not in (None, False)}


def object_of(args):
    """The object the object options name (no gripper: a trials folder records its own)."""
    from mjx_pick.core.objects import load_object

    return load_object(
        args.object,
        px_per_mm=args.px_per_mm,
        thickness_mm=args.thickness_mm,
        mass_g=args.mass_g,
        density_kg_m3=args.density_kg_m3,
        unit=args.unit,
        pose=args.pose,
        pick_height_mm=args.pick_height_mm,
        simplify_mm=args.simplify_mm,
        material=args.material,
        largest_body=getattr(args, "largest_body", False),
        repair_volume_pct=getattr(args, "repair_volume_pct", None),
        repair_com_mm=getattr(args, "repair_com_mm", None),
        repair_bounds_mm=getattr(args, "repair_bounds_mm", None),
    )


def settings(args):
    from mjx_pick.core.physics import ContactParams, SolverParams, load_contact
    from mjx_pick.core.procedure import GraspConfig

    def contact():
        c = load_contact(args.contact)[0] if args.contact else ContactParams()
        return override(c, **setting_flags.given(args, "contact"))

    def solver():
        s = load_toml(SolverParams, args.solver) if args.solver else SolverParams()
        return override(s, **setting_flags.given(args, "solver"))

    def grasp():
        """The procedure, and the names of the fields the user set (file or flag)."""
        data = read_toml(args.grasp, "GraspConfig") if args.grasp else {}
        flags = setting_flags.given(args, "grasp")
        g = from_mapping(GraspConfig, data, where=Path(args.grasp or "").name)
        return override(g, **flags), set(data) | set(flags)

    return tuple(each_checked(contact, solver, grasp, lambda: pick_config(args)))


def check_contact_file(args, obj, gripper, grasp, solver) -> None:
    """Before any simulation: say (stderr) where --contact was fitted for another set-up."""
    if getattr(args, "contact", None):
        from mjx_pick.studies.calibration.outputs import contact_file_notes

        for line in contact_file_notes(args.contact, obj, gripper, grasp, solver):
            print(line, file=sys.stderr)


def pick_config(args):
    from mjx_pick.core.pickpoints import PickConfig

    return override(PickConfig(), **setting_flags.given(args, "picks"))


def override(obj, **values):
    values = {k: v for k, v in values.items() if v is not None}
    return dataclasses.replace(obj, **values) if values else obj


def base_settings(args):
    """Object, Settings (gripper + physics flags) and PickConfig from the shared options."""
    from mjx_pick.core.settings import Settings

    obj, gripper, contact, solver, grasp, picks_cfg = inputs_of(args)
    check_contact_file(args, obj, gripper, grasp, solver)
    return obj, Settings(gripper, contact, solver, grasp), picks_cfg


def run_options(args, picks_cfg=None):
    """The run options of a command (``studies.options.RunOptions``), built once from
    its arguments: the ones a command does not have keep their defaults."""
    from mjx_pick.studies.options import RunOptions

    given = {
        "n": getattr(args, "n", None),
        "seed": getattr(args, "seed", 0),
        "pick_config": picks_cfg,
        "backend": getattr(args, "backend", registry.AUTO),
        "batch_size": getattr(args, "batch_size", None),
        "out": getattr(args, "out", None),
        "overwrite": getattr(args, "overwrite", False),
        "resume": getattr(args, "resume", False),
        "ray": getattr(args, "ray", None),
        "progress": not getattr(args, "no_progress", True),
        "grasps": getattr(args, "grasps", None) or "topdown",
        "depth_mm": getattr(args, "depth_mm", None),
    }
    return RunOptions(**given)


def grippers(text: str):
    from mjx_pick.core.gripper import load_gripper

    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise ConfigError(f"--grippers {text!r}: give comma-separated presets or TOML files")
    return [load_gripper(n) for n in names]


def design_bounds(items: list[str]) -> dict:
    out = {}
    for item in items:
        name, sep, rng = item.partition("=")
        lo, sep2, hi = rng.partition(":")
        try:
            if not sep or not sep2:
                raise ValueError("write FIELD=LO:HI")
            out[name.strip()] = (float(lo), float(hi))
        except ValueError as err:
            raise ConfigError(f"--bound {item!r}: {err} (e.g. finger_width_mm=10:40)") from err
    return out


def name_ranges(items, flag: str) -> dict:
    """['name=a:b', ...] -> {name: (a, b)}; a bad item is an error naming it."""
    out = {}
    for item in items or []:
        name, _, rng = item.partition("=")
        parts = rng.split(":")
        try:
            a, b = (float(x) for x in parts)
        except ValueError:
            raise ConfigError(
                f"{flag} {item!r}: expected NAME=A:B with two numbers (e.g. pad_friction=0.3:1.2)"
            ) from None
        out[name.strip()] = (a, b)
    return out
