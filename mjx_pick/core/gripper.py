"""Parametric parallel-jaw (two-finger) gripper specs and the shipped presets.

Details: docs/model.md (core/gripper.py).
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

from mjx_pick.core import mjcf_gripper, urdf_gripper
from mjx_pick.core.config import (
    ConfigError,
    check_fields,
    check_name,
    from_mapping,
    read_toml,
    setting,
)


@dataclasses.dataclass(frozen=True)
class GripperSpec:
    """A two-finger parallel gripper. Defaults: Robotiq 2F-85 as used in the paper."""

    name: str = "robotiq-2f85"
    stroke_mm: float = setting(
        85.0,
        "mm",
        "largest distance between the pads' inner faces (> 2 x finger_depth_mm)",
        lo=0,
        hi=1000,
        lo_open=True,
    )
    finger_width_mm: float = setting(
        22.0,
        "mm",
        "pad width, across the closing direction (<= 10 x stroke_mm)",
        lo=0,
        lo_open=True,
    )
    finger_depth_mm: float = setting(
        8.0, "mm", "pad thickness along the closing direction", lo=0, lo_open=True
    )
    pad_height_mm: float = setting(38.0, "mm", "pad height (vertical)", lo=0, lo_open=True)
    # a grasp pose (a planner's, a data set's, a physical trial's) names the gripper's tool
    # centre point; the simulation grips with the pads' centre: where one lies from the
    # other (ABB's YuMi fingers: the tool tips 3.75 mm beyond the pads' centre)
    tcp_offset_mm: float = setting(
        0.0,
        "mm",
        "the tool centre point that grasp poses name, from the pads' centre along the "
        "approach (+: towards the fingertips)",
        lo=-1000,
        hi=1000,
    )
    force_min_n: float = setting(
        20.0, "N", "smallest grip force the gripper can be set to", lo=0, hi="force_max_n"
    )
    force_max_n: float = setting(
        235.0, "N", "largest grip force the gripper can be set to", lo=0, lo_open=True
    )
    # closing speed = rate of change of the opening (datasheet convention); each
    # finger moves at half of it
    speed_min_mm_s: float = setting(
        20.0,
        "mm/s",
        "slowest closing speed (rate of change of the opening)",
        lo=0,
        hi="speed_max_mm_s",
    )
    speed_max_mm_s: float = setting(
        150.0,
        "mm/s",
        "fastest closing speed (rate of change of the opening)",
        lo=0,
        lo_open=True,
    )
    finger_mass_g: float = setting(40.0, "g", "mass of one finger", lo=0, lo_open=True)
    body_mass_g: float = setting(
        925.0, "g", "mass of the gripper body (on the lift)", lo=0, lo_open=True
    )
    # drive: the finger servo that tracks the integrated speed command
    drive_stiffness_n_per_mm: float = setting(
        10.0,
        "N/mm",
        "finger servo stiffness (force per mm of lag behind its command)",
        lo=0,
        lo_open=True,
    )
    # the drive's reflected inertia: the motor's rotor and gears seen at the finger's
    # travel, J_rotor / r^2 with r the finger travel per radian of the motor; a 2F-85
    # class drive (J ~ 1e-7 kg m^2, ~75 mm/s per finger at 3,000-6,000 rpm) reflects
    # 2-7 kg. Off by default: it calms the pads of a finger that loses its part for a
    # step, but a heavy part sliding through the pads then hammers them with the
    # drive's momentum (above the gripper's maximum force; docs/physics.md)
    drive_inertia_kg: float = setting(
        0.0, "kg", "the finger drive's inertia at the finger (motor and gears)", lo=0
    )
    drive_damping_ns_per_mm: float = setting(0.02, "N s/mm", "finger servo damping", lo=0)
    # the pads' material, recorded with results (config.json) and shown in reports; the
    # physics comes from ContactParams (pad friction, stiffness), never from this name
    pad_material: str = "nbr"
    source: str = "Bencak et al. 2023, Fig. 10; Robotiq 2F-85 datasheet"
    # a real gripper's MJCF model (None: the parametric parallel jaw above); its
    # geometry fields are then measured from it
    mjcf: mjcf_gripper.MjcfGripper | None = None

    def __post_init__(self):
        check_name("gripper", self.name)
        o = f"gripper[{self.name}]"
        if isinstance(self.mjcf, dict):  # from a saved config (JSON) or a TOML table
            mjcf = from_mapping(mjcf_gripper.MjcfGripper, self.mjcf, where=f"{o}.mjcf")
            object.__setattr__(self, "mjcf", mjcf)
        if self.mjcf is not None:
            kin = mjcf_gripper.characterise(self.mjcf)
            weakest = float(kin.force_limit_n.min())
            if self.force_max_n > weakest * (1 + 1e-6):
                at = float(kin.opening[np.argmin(kin.force_limit_n)]) * 1e3
                raise ConfigError(
                    f"{o}.force_max_n = {self.force_max_n:g} is more than the actuator "
                    f"{self.mjcf.actuator!r} can push: its force limit gives {weakest:.1f} N "
                    f"per pad at a {at:.1f} mm opening; raise mjcf.actuator_forcerange or "
                    "lower force_max_n"
                )
            # an MJCF gripper's geometry is its model's: a sweep or design variant that
            # changes it would simulate a gripper other than the one it names
            for field, value in measured_fields(kin).items():
                if abs(getattr(self, field) - value) > 1e-9 * max(1.0, abs(value)):
                    raise ConfigError(
                        f"{o}.{field} = {getattr(self, field)!r} cannot be set: an MJCF "
                        f"gripper's {field} is measured from its model ({value:g}); "
                        "change the MJCF file instead"
                    )
        check_fields(self, o)
        # the two pads must fit side by side in the gripper body when fully open, and
        # a pad must be thinner than half the stroke so the fingers can close fully
        if 2 * self.finger_depth_mm >= self.stroke_mm:
            raise ConfigError(
                f"{o}: fingers cannot fit the stroke: 2 x finger_depth_mm = "
                f"{2 * self.finger_depth_mm:g} mm must be < stroke_mm = {self.stroke_mm:g} mm"
            )
        if self.finger_width_mm > 10 * self.stroke_mm:
            raise ConfigError(
                f"{o}.finger_width_mm = {self.finger_width_mm:g} is out of range: allowed "
                f"<= 10 x stroke_mm ({10 * self.stroke_mm:g})"
            )


def preset_names() -> list[str]:
    """Names of the shipped gripper presets (assets/grippers/*.toml)."""
    folder = resources.files("mjx_pick.assets") / "grippers"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_gripper(name_or_path: str | os.PathLike) -> GripperSpec:
    """A preset by name (e.g. "robotiq-2f85") or a gripper TOML file by path."""
    text = str(name_or_path)
    if text.endswith(".toml") or os.sep in text:
        return _load_file(Path(text))
    names = preset_names()
    if text not in names:
        raise ConfigError(
            f"unknown gripper preset {text!r}: choose one of {', '.join(names)} "
            "or pass a gripper TOML file"
        )
    with resources.as_file(resources.files("mjx_pick.assets") / "grippers" / f"{text}.toml") as p:
        return _load_file(p)


def _load_file(path: Path) -> GripperSpec:
    data = read_toml(path, "gripper")
    return gripper_from_data(data, path.name, path.parent)


# what a gripper TOML must say itself (unless it names a preset as its base): a
# missing one is an error, never a preset's value under the user's name
REQUIRED = (
    "name",
    "stroke_mm",
    "finger_width_mm",
    "finger_depth_mm",
    "pad_height_mm",
    "force_min_n",
    "force_max_n",
    "speed_min_mm_s",
    "speed_max_mm_s",
    "finger_mass_g",
    "body_mass_g",
)
# an MJCF gripper's geometry and masses are measured from its model
REQUIRED_MJCF = ("name", "force_min_n", "force_max_n", "speed_min_mm_s", "speed_max_mm_s")


def gripper_from_data(data: dict, where: str, folder: Path) -> GripperSpec:
    """A GripperSpec from a parsed gripper TOML (where: its name for messages; folder:
    where a relative MJCF path is read from).

    Every key of ``REQUIRED`` (an MJCF gripper: ``REQUIRED_MJCF``) must be given, or
    ``base = "PRESET"`` names the shipped preset whose values the file's keys replace;
    the file's name is then required still (a changed preset is another gripper).
    """
    data = dict(data)
    base = data.pop("base", None)
    known = {f.name for f in dataclasses.fields(GripperSpec)} | {"urdf"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(
            f"{where}: unknown setting(s) {', '.join(unknown)}; known: base, "
            f"{', '.join(sorted(known))}"
        )
    if base is not None:
        names = preset_names()
        if not isinstance(base, str) or base not in names:
            raise ConfigError(
                f"{where}: base = {base!r} is not a gripper preset: choose one of "
                f"{', '.join(names)}"
            )
        if "name" not in data:
            raise ConfigError(
                f'{where}: give the gripper a name (name = "..."): it differs from its '
                f"base {base!r}"
            )
        res = resources.files("mjx_pick.assets") / "grippers" / f"{base}.toml"
        with resources.as_file(res) as p:
            base_data = tomllib.loads(p.read_text())
            base_folder = p.parent
        models = ("mjcf", "urdf")
        if any(k in base_data for k in models) and not any(k in data for k in models):
            folder = base_folder
        elif any(k in data for k in models):  # the file's model replaces the base's
            base_data = {k: v for k, v in base_data.items() if k not in models}
        source = data.get("source", f"{where}, based on {base}: {base_data.get('source', '')}")
        data = {**base_data, **data, "source": source}
    if "mjcf" in data and "urdf" in data:
        raise ConfigError(f"{where}: give an [mjcf] or a [urdf] table, not both")
    model = "mjcf" in data or "urdf" in data
    need = REQUIRED_MJCF if model else REQUIRED
    missing = [k for k in need if k not in data]
    if missing:
        presets = ", ".join(preset_names())
        raise ConfigError(
            f"{where}: missing {', '.join(missing)}; a gripper file gives every one of "
            f'{", ".join(need)}, or names the preset it changes (base = "robotiq-2f85"; '
            f"presets: {presets})"
        )
    if model:
        return mjcf_gripper_spec(data, folder / where, folder=folder)
    return from_mapping(GripperSpec, data, where=where)


def mjcf_gripper_spec(data: dict, path: Path, folder: Path | None = None) -> GripperSpec:
    """A GripperSpec for an MJCF or URDF gripper TOML (already parsed): the [mjcf] or
    [urdf] table checked against the model, geometry and masses measured from it (a
    quasi-static close)."""
    data = dict(data)
    kind = "urdf" if "urdf" in data else "mjcf"
    table = data.pop(kind)
    if not isinstance(table, dict):
        raise ConfigError(f"{path.name}: {kind} must be a table ([{kind}])")
    given = sorted(set(data) & set(mjcf_gripper.GEOMETRY_FIELDS + MJCF_MEASURED))
    if given:
        raise ConfigError(
            f"{path.name}: {', '.join(given)} are measured from the {kind.upper()} model; "
            "remove them"
        )
    folder = folder if folder is not None else path.parent
    where = f"{path.name} [{kind}]"
    if kind == "urdf":
        urdf = from_mapping(urdf_gripper.UrdfGripper, table, where=where)
        try:
            mjcf = mjcf_gripper.from_urdf(urdf, folder)
            kin = mjcf_gripper.characterise(mjcf)
        except ConfigError as err:  # said in the words of the user's [urdf] table
            raise ConfigError(mjcf_gripper.in_urdf_words(str(err), urdf)) from None
    else:
        mjcf = from_mapping(mjcf_gripper.MjcfGripper, table, where=where)
        mjcf = mjcf_gripper.resolve(mjcf, folder)
        kin = mjcf_gripper.characterise(mjcf)
    spec = from_mapping(GripperSpec, data, where=path.name)
    return dataclasses.replace(spec, mjcf=mjcf, **measured_fields(kin))


def measured_fields(kin: mjcf_gripper.Kinematics) -> dict[str, float]:
    """The GripperSpec fields an MJCF gripper's model sets (geometry, masses, drive)."""
    return {
        "stroke_mm": round(kin.stroke_m * 1e3, 3),
        "finger_width_mm": round(kin.pad_width_m * 1e3, 3),
        "finger_depth_mm": round(kin.pad_depth_m * 1e3, 3),
        "pad_height_mm": round(kin.pad_height_m * 1e3, 3),
        "finger_mass_g": round(kin.finger_mass_kg * 1e3, 3),
        "body_mass_g": round(kin.mass_kg * 1e3, 3),
        # where the stroke is stiffest (the kernels use the table along the stroke)
        "drive_stiffness_n_per_mm": round(float(kin.stiffness_n_per_m.max()) * 1e-3, 6),
    }


# besides the geometry: measured from an MJCF model, never set by its TOML
MJCF_MEASURED = ("finger_mass_g", "body_mass_g", "drive_stiffness_n_per_mm")
