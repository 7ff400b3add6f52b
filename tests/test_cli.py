"""A CLI that explains itself: every flag's help (unit, default), `mjx-pick params` read
from the settings' own declarations, and progress that reads right in a log."""

import argparse
import dataclasses
import io
import re
import subprocess
import sys

import pytest

import mjx_pick as mp
from mjx_pick.cli import build_parser, main, setting_flags
from mjx_pick.core.config import ConfigError
from mjx_pick.core.pickpoints import PickConfig
from mjx_pick.outputs.progress import ProgressBar
from mjx_pick.studies.sweeps import SECTIONS, describe_params, numeric_fields

# what a number's help must name: a unit, or that it is a pure number of some kind
UNITS = re.compile(
    r"\b(mm|um|N|s|deg|g|kg/m\^3|pixels per mm|coefficient|fraction|dimensionless|score|"
    r"multiple of real time)\b"
)
# flags that override one settings field, and the field: their help states its default
OVERRIDES = {
    setting_flags.flag(name): (section, name)
    for section, name in (*setting_flags.PHYSICS_FLAGS, *setting_flags.PICK_FLAGS)
}


def _parsers(parser=None, name="mjx-pick"):
    """(name, parser) of the root parser and every subcommand's, nested ones too
    (``trials plan``)."""
    parser = parser or build_parser()
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, sub_name if name == "mjx-pick" else f"{name} {sub_name}")


def test_every_flag_has_help_with_its_unit_and_default():
    sections = {**SECTIONS, "picks": PickConfig}
    missing, unitless, no_default, drift = [], [], [], []
    for name, parser in _parsers():
        text = parser.format_help()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            flag = "/".join(action.option_strings) or action.dest
            where = f"{name} {flag}"
            if not (action.help or "").strip():
                missing.append(where)
                continue
            kind = getattr(action.type, "__name__", None)  # a setting flag's: its field's type
            if kind == "float" and not UNITS.search(str(action.help)):
                unitless.append(where)
            shown = str(action.help).replace("%(default)s", str(action.default))
            if action.option_strings and action.default not in (None, False, argparse.SUPPRESS):
                if f"(default: {action.default})" not in " ".join(text.split()):
                    no_default.append(where)
            field = OVERRIDES.get(action.option_strings[0] if action.option_strings else "")
            if field:
                value = next(
                    f.default for f in dataclasses.fields(sections[field[0]]) if f.name == field[1]
                )
                value = f"{value:g}" if isinstance(value, float) else str(value)
                if not re.search(rf"\(default: {re.escape(value)}[,)]", shown):
                    drift.append(f"{where}: says {shown!r}, the default is {value}")
    assert not missing, f"flags without help: {missing}"
    assert not unitless, f"number flags whose help names no unit: {unitless}"
    assert not no_default, f"defaults not shown in --help: {no_default}"
    assert not drift, drift


def test_help_shows_defaults_and_units(capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "pick-points to generate (Normal mode) (default: 200)" in text
    assert "desired pad force (within the gripper's force range), N; x > 0 (default: 50," in text
    assert "(default: None)" not in text


def test_params_come_from_the_settings_declarations(capsys):
    rows = describe_params()
    names = {r["name"] for r in rows}
    for section, cls in {**SECTIONS, "picks": PickConfig}.items():
        for field in numeric_fields(cls):
            assert f"{section}.{field}" in names
    for r in rows:
        assert r["unit"] and r["meaning"], f"{r['name']} declares no unit or meaning"
    by_name = {r["name"]: r for r in rows}
    assert by_name["contact.pad_friction"]["range"] == "0 < x <= 5"
    assert by_name["gripper.force_min_n"]["range"] == "0 <= x <= force_max_n"
    assert by_name["grasp.grip_force_n"]["aliases"] == ["controller.force_n"]
    assert not by_name["picks.min_coverage"]["sweepable"]
    assert main(["params", "grasp.lift"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"grasp\.lift_height_mm\s+100\s+mm\s+0 < x <= 2000\s+lift height", out)
    assert "contact." not in out
    assert main(["params", "nope"]) == 2
    assert "no parameter starts with 'nope'" in capsys.readouterr().err


def test_the_printed_ranges_are_the_ones_enforced():
    # the range `params` prints and the one the dataclass checks are one declaration
    # (config.setting): a value just past either end is a ConfigError naming the field
    from mjx_pick.core.config import _bound, range_text

    checked = 0
    printed = {r["name"]: r["range"] for r in describe_params()}
    for section, cls in {**SECTIONS, "picks": PickConfig}.items():
        base = cls()
        for f in dataclasses.fields(cls):
            if f.name not in numeric_fields(cls):
                continue
            lo, hi, lo_open, hi_open = f.metadata["range"]
            assert printed[f"{section}.{f.name}"] == range_text(f.metadata["range"])
            kind = float if isinstance(getattr(base, f.name), float | None) else int
            for bound, open_, sign in ((lo, lo_open, -1), (hi, hi_open, 1)):
                if bound is None:
                    continue
                value = _bound(base, bound)
                bad = value if open_ else value + sign * max(1e-6, 1e-3 * abs(value))
                if kind is int and not open_:
                    bad = value + sign
                with pytest.raises(ConfigError, match=rf"\b{f.name} = .* out of range"):
                    dataclasses.replace(base, **{f.name: kind(bad)})
                checked += 1
    assert checked > 60


def test_a_settings_value_out_of_range_names_field_value_and_range():
    with pytest.raises(ConfigError, match=r"grasp\.hold_s = -1 is out of range: allowed 0 <="):
        mp.GraspConfig(hold_s=-1)
    with pytest.raises(ConfigError, match=r"force_min_n = 300 .* <= force_min_n <= 235"):
        mp.GripperSpec(force_min_n=300)
    # a bound read from another field is checked after that field itself
    with pytest.raises(ConfigError, match=r"force_max_n = 'x' must be a number"):
        mp.GripperSpec(force_max_n="x")


def _lines(feed, **kw) -> str:
    sink = io.StringIO()  # not a terminal: whole lines
    with ProgressBar("simulating", "pick", file=sink, **kw) as bar:
        feed(bar)
    return sink.getvalue()


def test_progress_without_a_terminal_writes_the_last_line_once():
    # tqdm redraws with "\r" and draws its final state again on close(): a log kept
    # the 100 % line twice. Without a terminal the bar writes whole lines instead.
    def feed(bar):
        for done in (0, 3, 5, 10):
            bar(done, 10)

    text = _lines(feed)
    assert "\r" not in text
    lines = text.splitlines()
    assert sum("100%" in line for line in lines) == 1, text
    assert lines[-1].startswith("simulating: 100% 10/10 pick"), text
    assert [ln.split("%")[0].split()[-1] for ln in lines] == ["30", "50", "100"]


def test_progress_over_several_runs_adds_up():
    # a study's rounds: each run reports (0, total) first; the bar's total grows
    def feed(bar):
        for total in (4, 6):
            bar(0, total)
            bar(total, total)

    lines = _lines(feed).splitlines()
    assert lines[-1].startswith("simulating: 100% 10/10 pick"), lines
    assert sum("10/10" in line for line in lines) == 1
    assert _lines(lambda bar: bar(5, 5), enabled=False) == ""


def test_progress_on_a_terminal_is_a_tqdm_bar_over_every_run():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    sink = Terminal()
    with ProgressBar("design", "sim", file=sink) as bar:
        for total in (4, 6):
            bar(0, total)
            bar(total, total)
        assert (bar.done, bar.total) == (10, 10)
    assert "\r" in sink.getvalue() and sink.getvalue().rstrip().split("\r")[-1].startswith(
        "design: 100%"
    )


def test_every_bad_input_is_reported_at_once(tmp_path, capsys):
    # three wrong inputs in three places (gripper, contact, solver): one run names them
    # all, before anything is simulated or written
    out = tmp_path / "never"
    argv = ["evaluate", "block", "--gripper", "nosuch", "--pad-friction", "-1"]
    argv += ["--timestep-s", "5", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("mjx-pick: error: 3 problems:")
    for part in (
        "unknown gripper preset 'nosuch'",
        "contact.pad_friction = -1.0",
        "solver.timestep_s = 5.0",
    ):
        assert part in err
    assert not out.exists()


def test_choosing_mjx_by_name_says_it_is_not_a_label_backend(tmp_path, capsys):
    # a bad input ends the run before anything is simulated: the note comes first
    argv = ["evaluate", "block", "--backend", "mjx", "--pad-friction", "-1"]
    assert main([*argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mjx-pick: note: --backend mjx is MJX's JAX physics")
    assert "use --backend mujoco or warp" in err
    assert main(["evaluate", "block", "--pad-friction", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "note:" not in capsys.readouterr().err  # auto: never said


def test_the_import_time_counts_from_the_interpreter_not_a_shell_before_it():
    # `bash -c "... && pip install . && mjx-pick ..."` execs mjx-pick in the shell's own
    # process, which the kernel dates to the shell's start (before the install): that
    # time is not the CLI's. A process that was the interpreter from its start keeps
    # the kernel's count, which sees the imports before the CLI's own clock loaded.
    age = "import mjx_pick.cli.clock as c; print(c.process_age_s())"
    shell = subprocess.run(
        ["bash", "-c", f'sleep 6; exec "{sys.executable}" -c "{age}"'],
        capture_output=True,
        text=True,
        check=True,
    )
    assert float(shell.stdout) < 3, shell.stdout
    slow = subprocess.run(
        [sys.executable, "-c", f"import time; time.sleep(2); {age}"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert 2 <= float(slow.stdout) < 5, slow.stdout
