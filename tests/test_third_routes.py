"""Nothing silent, third routes: each class of wrong answer closed once for every route
-- one reader of a user's text files, user text escaped wherever it is written, only a
run's own recorded files ever removed, nothing written by a refused command, no number
silently changed, an estimate before a long job. Each test drives the installed
``mjx-pick`` command the way a user would."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from test_second_routes import MJX_PICK, cli

FAST = ["--backend", "mujoco", "--no-progress", "--lift-height-mm", "5", "--hold-s", "0.05"]
SHIPPED = Path(__file__).resolve().parents[1] / "mjx_pick" / "assets"


# ------------------------------------------------------------ one reader of text files
LATIN1 = "# Reibung f\xfcr Gummi\n".encode("latin-1")


@pytest.mark.parametrize(
    "flag, body",
    [
        ("--contact", b"pad_friction = 0.9\n"),
        ("--solver", b"timestep_s = 0.001\n"),
        ("--grasp", b"hold_s = 0.1\n"),
        ("--gripper-file", b'base = "robotiq-2f85"\nname = "g"\n'),
        ("--picks", b"x_mm,y_mm,yaw_deg\n0,0,0\n"),
    ],
)
def test_a_settings_file_that_is_not_utf8_is_refused_by_name(flag, body, tmp_path):
    suffix = ".csv" if flag == "--picks" else ".toml"
    f = tmp_path / f"latin{suffix}"
    f.write_bytes(body + LATIN1 if suffix == ".csv" else LATIN1 + body)
    size = [] if flag == "--picks" else ["--n", "2"]
    res = cli("evaluate", "block", flag, f, *size, "--out", tmp_path / "never", *FAST)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert f"{str(f)!r} is not UTF-8 text: line " in res.stderr
    assert "0xfc" in res.stderr
    assert not (tmp_path / "never").exists()


def test_an_outcomes_record_that_is_not_utf8_is_refused_by_name(tmp_path):
    csv = tmp_path / "mine.csv"
    shutil.copy(SHIPPED / "outcomes" / "block_1kg_rg2.csv", csv)
    record = (SHIPPED / "outcomes" / "block_1kg_rg2.toml").read_bytes()
    (tmp_path / "mine.toml").write_bytes(LATIN1 + record)
    argv = ["calibrate", csv, "block", "--mass-g", "1000", "--gripper", "onrobot-rg2"]
    res = cli(*argv, "--steps", "1", "--out", tmp_path / "never", *FAST[:3], check=False)
    assert "mine.toml' is not UTF-8 text: line 1 holds the byte 0xfc" in res.stderr
    assert not (tmp_path / "never").exists()


# ------------------------------------------------ user text escaped wherever it goes
# names the name rule lets through, each holding what one format or another reads as
# markup: a double quote (XML, TOML), '<' and '&' (XML, HTML), an emoji (json.dumps
# writes it as surrogate escapes TOML refuses), an apostrophe and '$' (a shell line)
NAMES = ['grip "q"', "grip <a & b>", "grip 🤖"]  # more in AWKWARD, and in the probes


def _gripper_file(folder: Path, name: str) -> Path:
    quoted = name.replace("\\", "\\\\").replace('"', '\\"').replace("\t", "\\t")
    f = folder / "gripper.toml"
    f.write_text(f'base = "robotiq-2f85"\nname = "{quoted}"\n', "utf-8")
    return f


def _scene_model_name(run: Path) -> str:
    """scene.xml parsed by a strict XML parser (a file that is not well-formed raises):
    its model's name."""
    import xml.etree.ElementTree as ET

    return ET.parse(run / "scene.xml").getroot().get("model")


@pytest.mark.parametrize("name", NAMES)
def test_a_gripper_name_of_any_character_reaches_the_model_intact(name, tmp_path):
    out = tmp_path / "run"
    argv = ["evaluate", "block", "--gripper-file", _gripper_file(tmp_path, name)]
    cli(*argv, "--n", "2", "--traces", "0", "--out", out, *FAST, check=True)
    assert _scene_model_name(out) == f"mjx_pick block {name}"


def test_a_photo_or_mesh_named_with_markup_characters_is_simulated(tmp_path):
    import trimesh

    photo = tmp_path / 'bracket "v2".png'
    shutil.copy(SHIPPED / "objects" / "block.png", photo)
    mesh = tmp_path / "part <1> & 🤖.stl"
    trimesh.creation.box([30.0, 20.0, 15.0]).export(mesh)
    for source, size in (
        (photo, ["--px-per-mm", "10", "--thickness-mm", "20", "--mass-g", "43.2"]),
        (mesh, ["--unit", "mm", "--mass-g", "9"]),
    ):
        out = tmp_path / f"run-{source.suffix[1:]}"
        cli("evaluate", source, *size, "--n", "2", "--traces", "0", "--out", out, *FAST, check=True)
        assert _scene_model_name(out) == f"mjx_pick {source.stem} robotiq-2f85"


def test_a_name_the_name_rule_refuses_is_refused_before_work(tmp_path):
    photo = tmp_path / "line\nbreak.png"
    shutil.copy(SHIPPED / "objects" / "block.png", photo)
    size = ["--px-per-mm", "10", "--thickness-mm", "20", "--mass-g", "43.2"]
    res = cli("evaluate", photo, *size, "--out", tmp_path / "never", *FAST, check=False)
    assert "an object is named after its file" in res.stderr and "rename the file" in res.stderr
    gripper = _gripper_file(tmp_path, "tab\there")
    res = cli("evaluate", "block", "--gripper-file", gripper, "--out", tmp_path / "never", *FAST)
    assert res.returncode == 2 and "gripper.name = 'tab\\there' is not allowed" in res.stderr
    assert not (tmp_path / "never").exists()


def test_names_reach_toml_html_and_shell_lines_intact(tmp_path):
    """A design's best_gripper.toml, a fit's contact.toml, a report's HTML and the
    command line the CLI prints: each read back by its own format's parser (a design
    run itself: the probes, benchmarks/probes/third_routes.py)."""
    import dataclasses
    import html.parser
    import shlex
    import tomllib

    import mjx_pick as mp
    from mjx_pick.core.config import to_toml

    name = 'grip "q" <&> 🤖'
    _gripper_file(tmp_path, name)
    # what a design writes as best_gripper.toml (to_toml), read back
    best = dataclasses.replace(mp.load_gripper("robotiq-2f85"), name=f"{name}~w20")
    assert tomllib.loads(to_toml(best))["name"] == f"{name}~w20"

    # a fit on an object whose name holds the same characters, into a folder with a space
    photo = tmp_path / f"{name}.png"
    shutil.copy(SHIPPED / "objects" / "block.png", photo)
    rows = (SHIPPED / "outcomes" / "block_1kg_rg2.csv").read_text().splitlines()
    (tmp_path / "mine.csv").write_text("\n".join(rows[:1] + rows[4:8]) + "\n")
    fit = tmp_path / "my fit"
    argv = ["calibrate", tmp_path / "mine.csv", photo, "--px-per-mm", "10"]
    argv += ["--thickness-mm", "20", "--mass-g", "1000", "--gripper", "onrobot-rg2"]
    argv += ["--estimator", "random", "--steps", "0", "--no-identify"]
    res = cli(*argv, "--backend", "mujoco", "--no-progress", "--out", fit, check=True)
    contact = tomllib.loads((fit / "contact.toml").read_text("utf-8"))
    assert contact["fitted_for"]["object"] == name
    command = res.stdout.split("use: ")[-1].strip()
    assert shlex.split(command)[-1] == str(fit / "contact.toml")

    # the report of a run with both names: its title as an HTML parser reads it
    run = tmp_path / "run"
    argv = ["evaluate", photo, "--px-per-mm", "10", "--thickness-mm", "20", "--mass-g", "43.2"]
    argv += ["--gripper-file", tmp_path / "gripper.toml", "--n", "2", "--traces", "0"]
    cli(*argv, "--out", run, *FAST, check=True)
    cli("report", run, "--no-animations", "--no-progress", check=True)

    class Title(html.parser.HTMLParser):
        inside, text = False, ""

        def handle_starttag(self, tag, attrs):
            self.inside = tag == "title"

        def handle_endtag(self, tag):
            self.inside = False

        def handle_data(self, data):
            self.text += data if self.inside else ""

    parser = Title()
    parser.feed((run / "report.html").read_text("utf-8"))
    assert parser.text == f"mjx_pick report: {name}"


# every format's escape, read back by that format's own parser: text that reads as
# markup, quoting or an escape in one format or another, and Unicode beyond the BMP
AWKWARD = [
    'a "b"',
    "a 'b'",
    "<tag attr='x'>",
    "&amp; & &#10;",
    "back\\slash \\n \\u0041",
    "tab\there",
    "new\nline",
    "cr\rhere",
    "del\x7f",
    "emoji 🤖 and ✓",
    "ümlaut Grüße",
    "$HOME `id` $(id) ;|&",
    "*?[]{}~",
    "  spaces  ",
    "",
    "]]> --> <!--",
    "\u2028line sep\u2029",
    "right-to-left \u202e",
    "zero\u200bwidth",
    "a" * 300,
]


@pytest.mark.parametrize("text", AWKWARD)
def test_each_escape_reads_back_in_its_own_format(text):
    import html
    import shlex
    import tomllib
    import xml.etree.ElementTree as ET

    from mjx_pick.core.escape import html_text, shell_word, toml_string, xml_attr

    assert ET.fromstring(f'<m a="{xml_attr(text)}"/>').get("a") == text
    assert tomllib.loads(f"k = {toml_string(text)}")["k"] == text
    assert html.unescape(html_text(text)) == text and "<" not in html_text(text)
    assert shlex.split(f"cmd {shell_word(text)}") == ["cmd", text]


def test_text_xml_cannot_hold_is_replaced_not_written_raw():
    import xml.etree.ElementTree as ET

    from mjx_pick.core.escape import xml_attr

    text = "bell\x07 nul\x00 esc\x1b"
    assert ET.fromstring(f'<m a="{xml_attr(text)}"/>').get("a") == "bell\ufffd nul\ufffd esc\ufffd"


# ------------------------------ only the files a run recorded writing are ever removed
def _users_files(folder: Path) -> dict[Path, bytes]:
    """A user's notes and photos put into a run folder; {path: content}."""
    files = {folder / "notes.txt": b"cell 3: fixture moved"}
    files[folder / "photos" / "cell.jpg"] = b"\xff\xd8"
    files[folder / "cad" / "fixture.step"] = b"ISO-10303-21;"
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def _killed_before_its_first_chunk(out: Path) -> None:
    """An evaluate run SIGKILLed once it claimed out and wrote its configuration, before
    any chunk was saved."""
    import os
    import signal
    import time

    argv = ["evaluate", "block", "--n", "4000", "--chunk-size", "4000", "--out", out, *FAST]
    proc = subprocess.Popen(MJX_PICK.split() + list(map(str, argv)), stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (out / "scene.xml").is_file() and time.monotonic() < deadline:
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert not list(out.glob("chunks/part-*"))


def test_a_rerun_after_a_killed_run_keeps_the_files_the_user_added(tmp_path):
    out = tmp_path / "proj"
    _killed_before_its_first_chunk(out)
    mine = _users_files(out)
    res = cli("evaluate", "block", "--n", "8", "--seed", "5", "--out", out, *FAST, check=True)
    assert "replacing the files of an unfinished" in res.stderr
    assert "kept 3 file(s) no mjx-pick run recorded writing" in res.stderr
    assert {p: p.read_bytes() for p in mine} == mine
    assert (out / "results.parquet").is_file()


def test_a_refused_command_writes_nothing_and_a_later_run_keeps_the_users_files(tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    argv = ["sweep", "block", "--param", "controller.force_n=20,300", "--n", "8", "--out", "."]
    res = cli(*argv, *FAST, cwd=work, check=False)
    assert "sweep variant grasp.grip_force_n=300" in res.stderr
    assert sorted(work.iterdir()) == []  # no manifest, no lock file
    mine = _users_files(work)
    res = cli("evaluate", "block", "--n", "8", "--out", ".", *FAST, cwd=work, check=False)
    assert "holds files that mjx-pick did not write (cad, notes.txt, photos)" in res.stderr
    assert {p: p.read_bytes() for p in mine} == mine
    assert sorted(p.name for p in work.iterdir()) == ["cad", "notes.txt", "photos"]


def test_a_folder_of_foreign_files_gets_no_lock_file(tmp_path):
    import os

    etc = tmp_path / "etc"
    etc.mkdir()
    (etc / "passwd").write_text("root:x:0:0")
    cli("evaluate", "block", "--n", "2", "--out", etc, *FAST, check=False)
    assert sorted(p.name for p in etc.iterdir()) == ["passwd"]
    if os.geteuid() == 0 and not Path("/.mjx_pick.lock").exists():  # root writes anywhere
        try:
            res = cli("evaluate", "block", "--n", "2", "--out", "/", *FAST, check=False)
            assert "holds files that mjx-pick did not write" in res.stderr
            assert not Path("/.mjx_pick.lock").exists()
        finally:
            Path("/.mjx_pick.lock").unlink(missing_ok=True)


def test_overwrite_removes_the_runs_files_and_its_reports_not_the_users(tmp_path):
    out = tmp_path / "run"
    cli("evaluate", "block", "--n", "2", "--traces", "1", "--out", out, *FAST, check=True)
    cli("report", out, "--no-animations", "--no-progress", check=True)
    assert (out / "traces.parquet").is_file() and (out / "report.html").is_file()
    mine = _users_files(out)
    argv = ["evaluate", "block", "--n", "2", "--seed", "1", "--traces", "0", "--overwrite"]
    res = cli(*argv, "--out", out, *FAST, check=True)
    # the earlier run's traces and report are gone (no stale file beside new results)
    assert not (out / "traces.parquet").exists() and not (out / "report.html").exists()
    assert not list(out.glob("forces_*.png")) and not (out / "score_map.png").exists()
    assert {p: p.read_bytes() for p in mine} == mine
    assert "kept 3 file(s)" in res.stderr


def test_a_folder_an_older_version_wrote_is_not_emptied_blind(tmp_path):
    import json

    out = tmp_path / "old"
    out.mkdir()
    manifest = {"command": "evaluate", "config_key": "k", "status": "failed"}
    (out / "mjx_pick_run.json").write_text(json.dumps(manifest))
    (out / "results.parquet").write_bytes(b"x")
    res = cli("evaluate", "block", "--n", "2", "--overwrite", "--out", out, *FAST, check=False)
    assert "did not record the files it wrote (results.parquet)" in res.stderr
    assert (out / "results.parquet").read_bytes() == b"x"


def test_a_journal_never_reaches_out_of_its_folder(tmp_path):
    import json

    from mjx_pick.outputs.rundir import JOURNAL, remove_recorded

    outside = tmp_path / "outside.txt"
    outside.write_text("keep")
    run = tmp_path / "run"
    (run / "sub").mkdir(parents=True)
    (run / "link").symlink_to(tmp_path)
    (run / "sub" / "own.txt").write_text("x")
    entries = ["../outside.txt", str(outside), "link/outside.txt", "sub/own.txt", "", "/"]
    (run / JOURNAL).write_text("".join(json.dumps(e) + "\n" for e in entries) + '"cut')
    remove_recorded(run)
    assert outside.read_text() == "keep"
    assert not (run / "sub").exists()  # its one recorded file removed, then the folder


# ------------------------------------------ nothing silently ignored, capped or redrawn
@pytest.fixture(scope="module")
def picks_file(tmp_path_factory) -> Path:
    f = tmp_path_factory.mktemp("picks") / "mine.csv"
    f.write_text("x_mm,y_mm,yaw_deg\n0,0,0\n0,0,90\n1,0,0\n0,1,90\n")
    return f


@pytest.mark.parametrize(
    "argv, said",
    [
        (["evaluate", "block", "--out", ""], "--out '': empty"),
        (["picks", "block", "--out", " "], "--out ' ': empty"),
        (["sweep", "block", "--param", "contact.pad_friction=0.5,0.9", "--out", ""], "empty"),
        (["evaluate", "block", "--picks", "PICKS", "--n", "500"], "--n 500 with the pick-points"),
        (
            ["evaluate", "block", "--picks", "PICKS", "--until", "2", "--max", "16"],
            "it cannot take the pick-points given (--picks)",
        ),
        (["evaluate", "block", "--until", "2", "--n", "50"], "--n 50 with --until 2"),
        (["evaluate", "block", "--max", "16"], "--max 16 bounds Optimization mode only"),
        (["evaluate", "block", "--skip-infeasible"], "--skip-infeasible applies to a picks"),
        (
            ["evaluate", "block", "--fingertip-clearance-mm", "100"],
            "fingertip_clearance_mm = 100 is above a quarter of object 'block''s height "
            "(20 mm): allowed at most 5 mm",
        ),
        (["sweep", "block", "--param", "grasp.fingertip_clearance_mm=1,8"], "=8: grasp.finger"),
        (["evaluate", "block", "--lift-height-mm", "0.001"], "allowed lift_height_mm >= 5"),
        (["design", "block", "--bound", "finger_width_mm=-10:40"], "finger_width_mm = -10.0 is"),
        (["design", "block", "--bound", "stroke_mm=50:5000"], "stroke_mm = 5000.0 is out of"),
    ],
)
def test_an_input_the_run_would_ignore_cap_or_redraw_is_refused(argv, said, picks_file, tmp_path):
    argv = [picks_file if a == "PICKS" else a for a in argv]
    extra = [] if "--out" in argv else ["--out", tmp_path / "never"]
    if argv[0] != "picks":  # the simulating commands' fast settings, unless the case's own
        extra += FAST[:3] + ([] if "--lift-height-mm" in argv else FAST[3:])
    res = cli(*argv, *extra, cwd=tmp_path, check=False)
    assert res.returncode == 2, res.stderr[-2000:]
    assert said in res.stderr, res.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a refused command wrote"


def test_a_design_of_more_variants_than_its_bounds_hold_says_so_in_one_line(tmp_path):
    argv = ["design", "block", "--variants", "10000", "--bound", "finger_width_mm=10:40"]
    res = cli(*argv, "--out", tmp_path / "never", *FAST, check=False)
    assert "could draw only 301 distinct valid gripper variants" in res.stderr
    assert len(res.stderr) < 2000


# --------------------------------------- refused before writing; messages from what ran
@pytest.fixture(scope="module")
def untraced_run(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("untraced") / "run"
    res = cli("evaluate", "block", "--n", "4", "--traces", "0", "--out", out, *FAST, check=True)
    return out, res


def test_a_run_without_traces_does_not_say_it_wrote_them(untraced_run):
    out, res = untraced_run
    assert not (out / "traces.parquet").exists()
    last = res.stdout.strip().splitlines()[-1]
    assert last.startswith(f"results in {out}/") and "traces" not in last


@pytest.mark.parametrize("frame", ["nan,0,0,0,0,0", "1,2,3"])
def test_a_report_refuses_its_frame_before_writing_anything(frame, untraced_run, tmp_path):
    run, _ = untraced_run
    before = sorted(p.name for p in run.iterdir())
    res = cli("report", run, "--frame", frame, "--out", tmp_path / "rep", "--no-progress")
    assert res.returncode == 2 and "must be 6 finite numbers" in res.stderr, res.stderr[-2000:]
    assert not (tmp_path / "rep").exists()
    res = cli("report", run, "--frame", frame, "--no-progress", check=False)  # into the run
    assert sorted(p.name for p in run.iterdir()) == before


def test_a_fit_says_where_its_value_and_its_interval_lie_not_one_for_the_other(tmp_path):
    # one success at 14 N: any friction from the lower bound 0.05 up holds it, so the
    # interval spans the bounds; the value (the start, 0.86: no step) is on neither
    rows = (SHIPPED / "outcomes" / "block_1kg_rg2.csv").read_text().splitlines()
    csv = tmp_path / "one.csv"
    csv.write_text("\n".join([rows[0], rows[12]]) + "\n")
    argv = ["calibrate", csv, "block", "--mass-g", "1000", "--gripper", "onrobot-rg2"]
    argv += ["--steps", "0", "--backend", "mujoco", "--no-progress"]
    res = cli(*argv, "--out", tmp_path / "fit", check=True)
    line = next(t for t in res.stdout.splitlines() if t.startswith("pad_friction:"))
    assert "fit at its" not in line
    assert "its 95 % interval reaches its lower bound 0.05 and upper bound 2" in line
    assert "no estimator step was taken (--steps 0)" in res.stdout
    # without the check, the fit's record says that nothing was checked
    res = cli(*argv, "--no-identify", "--out", tmp_path / "quick", check=True)
    toml = (tmp_path / "quick" / "contact.toml").read_text()
    assert "not_identified = []" in toml and "identifiability_checked = false" in toml
    assert "identifiability not checked" in res.stdout
    assert "identifiability_checked = true" in (tmp_path / "fit" / "contact.toml").read_text()


# ------------------------------------------------- an estimate before any long job
@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "block", "--n", "100000000"],
        ["evaluate", "block", "--picks", "MILLION"],
        ["sweep", "block", "--param", "contact.pad_friction=0.2:1:5", "--n", "1000000"],
        ["robust", "block", "--n", "64", "--top-k", "16", "--m", "100000"],
        ["design", "block", "--bound", "finger_width_mm=10:40", "--rounds", "20"],
    ],
)
def test_a_long_job_says_how_long_and_waits_for_yes(argv, tmp_path, tmp_path_factory):
    if "MILLION" in argv:
        rows = tmp_path_factory.mktemp("million") / "million.csv"
        body = "".join(f"{i % 7},{i % 5},{i % 360}\n" for i in range(1_000_000))
        rows.write_text("x_mm,y_mm,yaw_deg\n" + body)
        argv = [rows if a == "MILLION" else a for a in argv]
    res = cli(*argv, "--out", tmp_path / "never", "--backend", "mujoco", "--no-progress")
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert "would take about" in res.stderr and "pass --yes to start it" in res.stderr
    assert "a second: mujoco on" in res.stderr
    assert not (tmp_path / "never").exists()


def test_yes_starts_a_long_job_and_says_its_estimate_first(tmp_path):
    import time

    argv = ["evaluate", "block", "--n", "100000", "--yes", "--backend", "mujoco"]
    proc = subprocess.Popen(
        MJX_PICK.split() + argv + ["--no-progress"], stderr=subprocess.PIPE, text=True
    )
    try:
        deadline, seen = time.monotonic() + 60, ""
        while "started (--yes)" not in seen and time.monotonic() < deadline:
            seen += proc.stderr.readline()
        assert "this evaluate: about" in seen and "started (--yes)" in seen, seen
    finally:
        proc.kill()
        proc.wait()
        proc.stderr.close()


def test_the_counted_simulations_are_those_a_study_runs(tmp_path):
    """duration.count against what the studies report having simulated."""
    import json

    from mjx_pick.studies import duration

    out = tmp_path / "design"
    argv = ["design", "block", "--bound", "finger_width_mm=15:30", "--variants", "4"]
    cli(*argv, "--rounds", "2", "--n", "4", "--out", out, *FAST, check=True)
    rollouts = json.loads((out / "design.json").read_text())["rollouts"]
    # the most it runs: a variant's infeasible pick-points of the shared set are not run
    most = duration.count("design", variants=4, rounds=2, n=4)
    assert 0.75 * most <= rollouts <= most
    assert duration.count("evaluate", n=8, step_check=True, stability_um=1.0) == 8 * 4
    assert duration.count("robust", top_k=3, m=5, n=None) == 15


def test_a_log_shows_progress_at_the_first_work_and_every_minute(monkeypatch):
    import io

    from mjx_pick.outputs import progress

    now = [0.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: now[0])
    sink = io.StringIO()  # not a terminal: lines
    with progress.ProgressBar("robust", "sim", file=sink) as bar:
        bar(0, 1_000_000)
        now[0] = 5.0
        bar(1024, 1_000_000)  # the first chunk: said at once, not at 10 %
        now[0] = 30.0
        bar(2048, 1_000_000)  # within the minute: quiet
        now[0] = 70.0
        bar(3072, 1_000_000)  # a minute after the last line
    lines = sink.getvalue().splitlines()
    assert [ln.split(" sim")[0] for ln in lines] == [
        "robust:   0% 1024/1000000",
        "robust:   0% 3072/1000000",
    ]


# ------------------------------------------------ what a user reads: no internals shown
def test_a_warning_is_one_line_without_its_source(tmp_path):
    argv = ["evaluate", "block", "--mass-g", "1000", "--gripper", "onrobot-rg2", "--n", "2"]
    res = cli(*argv, "--traces", "0", *FAST, check=True)
    assert "mjx-pick: warning: object 'block': mass_g = 1000" in res.stderr
    assert ".py:" not in res.stderr and "return object_from_polygon" not in res.stderr


def test_no_word_of_warp_where_warp_is_not_used_nor_of_the_display(tmp_path):
    broken = tmp_path / "site" / "warp"
    broken.mkdir(parents=True)
    (broken / "__init__.py").write_text("raise ImportError('no warp on this machine')\n")
    import os

    env = {
        **os.environ,
        "PYTHONPATH": f"{broken.parent}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    }
    # MJX's JAX physics (refused here for its settings, after MJX was imported)
    res = cli("evaluate", "block", "--backend", "mjx", "--n", "2", env=env, check=False)
    assert "mjx-pick: error:" in res.stderr  # the settings it refuses, as ever
    assert "Failed to import" not in res.stdout + res.stderr
    # a pick-point flag's type imports MuJoCo while parsing: the display choice came first
    res = cli("evaluate", "block", "--safety-zone-mm", "0", "--n", "2", *FAST, check=True)
    assert "use_offscreen_rendering" not in res.stderr


def test_a_urdf_grippers_error_names_its_urdf_key(tmp_path):
    shipped = SHIPPED / "grippers" / "robotiq-2f85-urdf.toml"
    text = shipped.read_text().replace('file = "', f'file = "{shipped.parent}/', 1)
    flipped = tmp_path / "flipped.toml"
    flipped.write_text(
        text.replace("mount_quat = [0.0, 1.0, 0.0, 0.0]", "mount_quat = [1, 0, 0, 0]")
    )
    res = cli("evaluate", "block", "--gripper-file", flipped, "--n", "2", *FAST, check=False)
    assert "[urdf] mount_quat: the pads must hang below the mount" in res.stderr
    assert "gripper.mjcf" not in res.stderr


def test_a_full_disk_names_the_file_it_could_not_write(tmp_path):
    import shlex

    # files of at most 20 kB, as a disk that fills (EFBIG, not ENOSPC: SIGXFSZ ignored),
    # set by a shell around the command: a preexec_fn would fork this process, whose
    # JAX threads make a fork unsafe (and a warning, an error here)
    out = tmp_path / "run"
    argv = ["evaluate", "block", "--n", "8", "--out", out, *FAST]
    command = shlex.join(MJX_PICK.split() + [str(a) for a in argv])
    res = subprocess.run(
        ["bash", "-c", f"trap '' XFSZ; ulimit -f 20; exec {command}"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    assert res.returncode == 1, res.stderr[-2000:]
    assert f"mjx-pick: error: {out}/" in res.stderr and "File too large" in res.stderr
