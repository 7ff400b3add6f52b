"""The settings a finished run recorded (its ``config.json``), read back."""

from __future__ import annotations

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, from_mapping
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.settings import Settings
from mjx_pick.outputs.rundir import changed_settings, flat_settings


def settings_of(config: dict, where: str) -> tuple[Settings, pp.PickConfig]:
    """The Settings and PickConfig an evaluate run's config.json (or a plan) records."""
    try:
        s = Settings(
            from_mapping(GripperSpec, config["gripper"], where=f"{where}: gripper"),
            from_mapping(ContactParams, config["contact"], where=f"{where}: contact"),
            from_mapping(SolverParams, config["solver"], where=f"{where}: solver"),
            from_mapping(GraspConfig, config["grasp"], where=f"{where}: grasp"),
        )
        picks = from_mapping(pp.PickConfig, config["picks"], where=f"{where}: picks")
    except KeyError as err:
        raise ConfigError(f"{where} does not record the {err.args[0]} settings") from None
    return s, picks


def settings_changes(recorded: tuple, given: tuple) -> list[str]:
    """Each setting of given (Settings, PickConfig) that differs from recorded's, as
    'grasp.hold_s: 0.2 -> 0.5' (where a file was read from is no setting)."""

    def flat(pair) -> dict:
        settings, picks = pair
        values = flat_settings({"settings": settings, "picks": picks})
        return {
            k.removeprefix("settings."): v for k, v in values.items() if not k.endswith(".source")
        }

    changes = changed_settings(flat(recorded), flat(given))
    return sorted(changes, key=lambda line: ".name:" not in line)  # a gripper's name first
