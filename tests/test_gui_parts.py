"""The GUI's parts without a browser: form validation, uploads, runs and their cancel."""

import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from mjx_pick.core.config import ConfigError
from mjx_pick.core.gripper import load_gripper
from mjx_pick.gui import forms, is_loopback, jobs
from mjx_pick.gui.uploads import check_upload, save_upload


def test_importing_the_package_does_not_import_the_web_framework():
    code = (
        "import sys, mjx_pick, mjx_pick.cli, mjx_pick.gui, mjx_pick.gui.app; "
        "print('nicegui' in sys.modules, 'fastapi' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


def values(**changes):
    v = forms.defaults(load_gripper("robotiq-2f85"))
    v.update({k.replace("__", "."): x for k, x in changes.items()})
    return v


def test_the_form_builds_the_settings_it_shows():
    g = load_gripper("robotiq-2f85")
    settings, errors = forms.build(values(grasp__grip_force_n=40.0, contact__pad_friction=0.6), g)
    assert errors == {}
    assert settings.grasp.grip_force_n == 40.0 and settings.contact.pad_friction == 0.6
    assert settings.gripper == g  # untouched: still the preset, under its name
    edited, _ = forms.build(values(gripper__stroke_mm=70.0), g)
    assert edited.gripper.stroke_mm == 70.0 and edited.gripper.name == "robotiq-2f85-edited"


def test_every_bad_field_gets_its_own_message():
    g = load_gripper("robotiq-2f85")
    settings, errors = forms.build(
        values(gripper__stroke_mm=-5.0, picks__min_coverage=1.5, grasp__kp_mm_s_per_n=None), g
    )
    assert settings is None
    assert set(errors) == {"gripper.stroke_mm", "picks.min_coverage", "grasp.kp_mm_s_per_n"}
    assert "stroke width (mm) = -5.0 is out of range" in errors["gripper.stroke_mm"]
    assert "minimum coverage = 1.5 is out of range" in errors["picks.min_coverage"]
    assert errors["grasp.kp_mm_s_per_n"] == "P gain is required"


def test_cross_field_rules_land_on_a_field():
    g = load_gripper("robotiq-2f85")
    _, errors = forms.build(values(gripper__finger_depth_mm=50.0), g)
    assert "fingers cannot fit the stroke" in errors["gripper.finger_depth_mm"]
    _, errors = forms.build(values(grasp__grip_force_n=500.0), g)
    assert "out of range for robotiq-2f85" in errors["grasp.grip_force_n"]


def test_gripper_toml_errors_name_the_problem():
    with pytest.raises(ConfigError, match="not valid TOML"):
        forms.gripper_from_toml("stroke_mm = = 1")
    with pytest.raises(ConfigError, match="unknown setting"):
        forms.gripper_from_toml('name = "g"\nstrok_mm = 80\n')
    with pytest.raises(ConfigError, match="empty"):
        forms.gripper_from_toml("")
    with pytest.raises(ConfigError, match="missing finger_width_mm"):
        forms.gripper_from_toml('name = "g"\nstroke_mm = 80.0\n')
    text = 'base = "robotiq-2f85"\nname = "g"\nstroke_mm = 80.0\n'
    assert forms.gripper_from_toml(text).stroke_mm == 80.0


@pytest.mark.parametrize(
    "start,end,step,expect",
    [
        (0.5, 0.9, 0.4, (0.5, 0.9)),
        (20, 50, 10, (20.0, 30.0, 40.0, 50.0)),
        (1, 1, 1, (1.0,)),
        (0.5, 0.9, 0.3, "step"),
        (0.9, 0.5, 0.1, "end"),
        (0.5, 0.9, 0, "step"),
        (None, 0.9, 0.1, "start"),
    ],
)
def test_sweep_values_from_start_end_step(start, end, step, expect):
    got, errors = forms.sweep_values(start, end, step)
    if isinstance(expect, tuple):
        assert errors == {} and got == pytest.approx(expect)
    else:
        assert got is None and list(errors) == [expect]


def test_uploads_are_checked_and_never_replace_another_file(tmp_path):
    root = Path(__file__).resolve().parents[1]
    data = (root / "mjx_pick" / "assets" / "objects" / "block.png").read_bytes()
    assert check_upload("block.png", len(data), data) == ""
    assert "not an image" in check_upload("notes.txt", 10)
    assert "too large" in check_upload("big.png", 21 * 2**20)
    assert "too large" not in check_upload("big.stl", 21 * 2**20)
    assert "cannot be read as an image" in check_upload("x.png", 5, b"hello")
    first = save_upload(data, "my part.png", tmp_path)
    again = save_upload(data, "my part.png", tmp_path)
    other = save_upload(b"other", "my part.png", tmp_path)
    assert first == again == tmp_path / "my_part.png"
    assert other == tmp_path / "my_part-2.png" and first.read_bytes() == data


def test_is_loopback():
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


def test_a_cancelled_run_keeps_its_chunks_and_resumes_from_the_cli(tmp_path):
    """Cancel = SIGINT to the CLI child: the folder is 'interrupted', chunks stay."""
    out = tmp_path / "run"
    # 100 chunks: the run goes on for seconds after its first chunk, so the cancel
    # lands mid-run on a fast machine too (30 picks once finished before the SIGINT)
    argv = ["evaluate", "block", "--n", "200", "--seed", "1", "--backend", "mujoco"]
    argv += ["--lift-height-mm", "20", "--hold-s", "0.1", "--traces", "1", "--no-progress"]
    argv += ["--chunk-size", "2", "--out", str(out)]
    job = jobs.Job(argv, tmp_path / "run.log", out, total=200, chunk=2).start()
    deadline = time.monotonic() + 240
    while not list((out / "chunks").glob("part-*.parquet")):
        assert job.running, (tmp_path / "run.log").read_text()
        assert time.monotonic() < deadline
        time.sleep(0.2)
    progress = job.poll()
    assert progress.state == "running" and 2 <= progress.done < 200
    job.cancel()
    job.wait(60)
    progress = job.poll()
    assert progress.state == "cancelled", (tmp_path / "run.log").read_text()
    kept = len(list((out / "chunks").glob("part-*.parquet")))
    assert 1 <= kept < 100
    assert json.loads((out / "mjx_pick_run.json").read_text())["status"] == "interrupted"
    assert job.command_line.startswith("mjx-pick evaluate block")
    done = subprocess.run(
        [sys.executable, "-m", "mjx_pick.cli", *argv, "--resume"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    table = pq.read_table(out / "results.parquet")
    assert table.num_rows == 200 and len(np.unique(np.asarray(table["pick_id"]))) == 200


def test_a_failed_run_reports_the_cli_error_line(tmp_path):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "mine.txt").write_text("not mjx-pick's")
    job = jobs.Job(["evaluate", "block", "--n", "2", "--out", str(out)], tmp_path / "x.log", out)
    job.start().wait(120)
    p = job.poll()
    assert p.state == "failed"
    assert "holds files that mjx-pick did not write" in p.message
    assert "Traceback" not in p.message


def test_run_inputs_never_replace_the_files_of_another_run(tmp_path):
    g = load_gripper("robotiq-2f85")
    a, _ = forms.build(values(), g)
    b, _ = forms.build(values(grasp__grip_force_n=30.0), g)
    first = forms.write_inputs(a, tmp_path / "run")
    same = forms.write_inputs(a, tmp_path / "run")
    other = forms.write_inputs(b, tmp_path / "run")
    assert first == same and first["grasp"].parent == tmp_path / "run"
    assert other["grasp"].parent == tmp_path / "run-2"
    assert "grip_force_n = 50.0" in first["grasp"].read_text()
    assert "grip_force_n = 30.0" in other["grasp"].read_text()
    flags = forms.cli_flags(b, other)
    assert flags[flags.index("--grasp") + 1] == str(other["grasp"])


def test_gripper_toml_and_outcomes_uploads_are_checked_before_they_are_read():
    from mjx_pick.gui.uploads import check_outcomes_upload, check_toml_upload

    assert check_toml_upload("g.toml", b'name = "g"') == ""
    assert "not a .toml file" in check_toml_upload("g.txt", b"")
    assert "g.toml: 65,537 bytes is too large (at most 65,536 bytes)" in check_toml_upload(
        "g.toml", b"#" * (64 * 2**10 + 1)
    )
    assert check_outcomes_upload("o.csv", b"x_mm,y_mm\n") == ""
    assert "o.xlsx: not a .csv file" in check_outcomes_upload("o.xlsx", b"")
    assert "o.csv: 6 MB is too large (at most 5 MB)" in check_outcomes_upload(
        "o.csv", b"x" * 6 * 2**20
    )
    assert "not a UTF-8 text file" in check_outcomes_upload("o.csv", b"\xff\xfe\x00")


def test_run_names_stay_inside_the_work_folder(tmp_path):
    from mjx_pick.gui.state import PageState

    state = PageState(tmp_path)
    assert state.run_folder(" gui-run ") == tmp_path / "gui-run"
    for bad in ("../outside", "", ".hidden", "a/b", "x" * 81):
        assert state.run_folder(bad) is None, bad


def test_progress_survives_chunks_removed_while_it_reads_them(tmp_path):
    # a complete evaluate removes its chunk files; the page may have just listed them
    gone = tmp_path / "part-0.parquet"
    kept = tmp_path / "part-1.parquet"
    kept.write_bytes(b"")
    assert jobs._newest_mtime([gone, kept]) == kept.stat().st_mtime
    assert jobs._newest_mtime([gone]) is None


class _Shown:
    """Stands in for a NiceGUI element: records what the panel shows."""

    text = ""
    options: dict = {}

    def set_text(self, text):
        self.text = text

    def set_options(self, options):
        self.options = options

    def set_value(self, value):
        pass

    def set_content(self, content):
        pass

    def set_visibility(self, visible):
        pass

    def props(self, *args, **kwargs):
        return self


def test_a_run_stays_current_until_the_panel_has_shown_its_end(tmp_path):
    # the child process exits up to one poll before the panel sees it: a run started in
    # that gap replaced the job whose end was never shown (its results never drawn)
    from mjx_pick.gui.page.job_panel import JobPanel

    panel = JobPanel.__new__(JobPanel)  # its logic without a browser
    panel.runs, panel.owner, panel.handlers = jobs.Runs(), None, {}
    panel.job, panel.on_end, panel.others = None, None, _Shown()
    panel.title, panel.status, panel.bar = _Shown(), _Shown(), _Shown()
    panel.command, panel.cancel_button, panel.card = _Shown(), _Shown(), _Shown()
    panel.warnings, panel.history, panel.listed = _Shown(), _Shown(), []
    panel.where = _Shown()
    ended = []
    job = jobs.Job(["--version"], tmp_path / "version.log")
    panel.start("version", job, _Shown(), ended.append)
    job.wait(120)
    assert not job.running
    where = _Shown()
    assert panel.busy(where) and "in progress" in where.text
    with pytest.raises(RuntimeError, match="a run is current"):
        second = jobs.Job(["--version"], tmp_path / "second.log")
        panel.start("second", second, _Shown(), ended.append)
    panel.poll()
    assert [p.state for p in ended] == ["complete"]
    assert panel.status.text.startswith("complete")
    assert not panel.busy(_Shown())


def test_a_run_runs_the_servers_package_not_the_working_directorys(tmp_path, monkeypatch):
    # a folder named like the package, or like one of its dependencies, where the server
    # was started (or on PYTHONPATH) must not be what a run imports
    here = tmp_path / "where-the-server-started"
    (here / "mjx_pick" / "cli").mkdir(parents=True)
    for init in ("mjx_pick/__init__.py", "mjx_pick/cli/__init__.py", "numpy.py"):
        (here / init).write_text(f"raise SystemExit('imported the shadowing {init}')\n")
    monkeypatch.chdir(here)
    monkeypatch.setenv("PYTHONPATH", str(here))
    job = jobs.Job(["evaluate", "--help"], tmp_path / "logs" / "help.log").start()
    job.wait(120)
    log = (tmp_path / "logs" / "help.log").read_text()
    assert job.poll().state == "complete", log
    assert "shadowing" not in log and "--chunk-size" in log


def test_a_run_never_writes_over_another_runs_log(tmp_path):
    log = tmp_path / "logs" / "run.log"
    log.parent.mkdir()
    log.write_text("the first run's log\n")
    job = jobs.Job(["--version"], log).start()
    job.wait(120)
    assert log.read_text() == "the first run's log\n"
    assert job.log == tmp_path / "logs" / "run-2.log"
    assert job.poll().state == "complete" and "mjx-pick" in job.log.read_text()


def test_evaluate_progress_counts_the_feasible_pick_points_and_never_goes_back(tmp_path):
    # asked for 50, of which the run found 10 feasible (config.json's n), chunks of 2
    out = tmp_path / "run"
    (out / "chunks").mkdir(parents=True)
    job = jobs.Job(["evaluate"], tmp_path / "run.log", out, total=50, chunk=64)
    p = job.poll()
    assert (p.done, p.total, p.message) == (0, 50, "checking the pick-points")
    (out / "config.json").write_text(json.dumps({"n": 10, "chunk_size": 2}))
    p = job.poll()
    assert (p.done, p.total, p.rate) == (0, 10, None) and "first chunk" in p.message
    for k in range(3):
        part = out / "chunks" / f"part-{k:05d}.parquet"
        part.write_bytes(b"")
        os.utime(part, (1000.0 + k, 1000.0 + k))  # one chunk a second
    p = job.poll()
    assert (p.done, p.total) == (6, 10)
    # the first chunk (compiling) starts the clock: 2 chunks of 2 in 2 s
    assert p.rate == pytest.approx(2.0) and p.eta_s == pytest.approx(2.0)
    for part in (out / "chunks").iterdir():  # a completing run removes its chunks
        part.unlink()
    assert job.poll().done == 6


def test_a_runs_warnings_reach_the_page(tmp_path):
    log = tmp_path / "run.log"
    log.write_text(
        "$ mjx-pick evaluate block --n 10000000\n"
        "/x/evaluation.py:355: UserWarning: only 65732 of 10000000 pick-points are feasible\n"
        "  picks_batch = pp.generate_normal(\n"
    )
    job = jobs.Job(["evaluate"], log)
    assert job.poll().warnings == ("only 65732 of 10000000 pick-points are feasible",)


def test_the_progress_chunk_moves_the_bar_every_2_percent():
    from mjx_pick.gui.page.job_panel import status_line

    assert [jobs.progress_chunk(n) for n in (1, 50, 51, 65_732)] == [1, 1, 2, 1315]
    running = jobs.Progress("running", 3, 10, 2.0, 3.5, 9.0, "", "pick-points")
    assert status_line(running) == (
        "running, 3/10 pick-points, 2.0 pick-points per s, about 4 s left, 9 s"
    )


def test_a_sweep_value_outside_its_range_is_refused_before_the_run():
    g = load_gripper("robotiq-2f85")
    settings, _ = forms.build(values(), g)
    assert forms.sweep_problem(settings, "contact.pad_friction", (0.4, 0.6)) == ""
    problem = forms.sweep_problem(settings, "contact.pad_friction", (0.0, 0.4))
    assert problem.startswith("pad friction = 0 cannot be simulated") and "0 <" in problem
    problem = forms.sweep_problem(settings, "grasp.grip_force_n", (50, 500))
    assert "grip force F_d = 500" in problem and "robotiq-2f85" in problem


def test_messages_use_the_forms_words_and_only_them():
    g = load_gripper("robotiq-2f85")
    _, errors = forms.build(values(gripper__stroke_mm=-5.0, contact__pad_friction=0.0), g)
    # no details line with the library's own text: its keys are the program's words
    assert errors["gripper.stroke_mm"] == (
        "stroke width (mm) = -5.0 is out of range: allowed 0 < stroke width (mm) <= 1000"
    )
    assert errors["contact.pad_friction"].startswith("pad friction = 0.0 is out of range")
    assert forms.user_words("P gain is required") == "P gain is required"
    from mjx_pick.gui.formatting import column_label

    assert column_label("robust_p") == "success probability under the errors"
    assert column_label("x_mm") == "object x under gripper (mm)"


SHORT = ["--backend", "mujoco", "--lift-height-mm", "20", "--hold-s", "0.1", "--no-progress"]


def warm_workers(tmp_path) -> "jobs.Workers":
    """The server's warm workers for a work folder, the MuJoCo C one started and ready."""
    workers = jobs.Workers(tmp_path / "logs")
    workers.prepare("mujoco")
    worker = workers.worker("mujoco")
    assert worker.ready.wait(180), (tmp_path / "logs" / "worker-mujoco.log").read_text()
    return workers


def test_a_second_job_reuses_the_warm_worker(tmp_path, monkeypatch):
    # the worker is started isolated like a job's own process: a package (or a
    # dependency) shadowed where the server started, or on PYTHONPATH, is not imported
    here = tmp_path / "where-the-server-started"
    (here / "mjx_pick" / "cli").mkdir(parents=True)
    for init in ("mjx_pick/__init__.py", "mjx_pick/cli/__init__.py", "numpy.py"):
        (here / init).write_text(f"raise SystemExit('imported the shadowing {init}')\n")
    monkeypatch.chdir(here)
    monkeypatch.setenv("PYTHONPATH", str(here))
    workers = warm_workers(tmp_path)
    try:
        pid = workers.worker("mujoco").pid
        logs = []
        for k in range(2):
            out = tmp_path / f"run{k}"
            argv = ["evaluate", "block", "--n", "4", "--seed", str(k), *SHORT, "--out", str(out)]
            job = jobs.Job(argv, tmp_path / "logs" / f"run{k}.log", out, 4, 4).start(workers)
            assert job.warm and job._proc.pid == pid
            job.wait(300)
            log = job.log.read_text()
            logs.append(log)
            p = job.poll()
            assert p.state == "complete" and (p.done, p.total) == (4, 4), log
            assert log.startswith(f"$ {job.command_line}\n") and "pick-points per s" in log
            assert "shadowing" not in log
            assert pq.read_table(out / "results.parquet").num_rows == 4
            assert json.loads((out / "mjx_pick_run.json").read_text())["status"] == "complete"
        worker = workers.worker("mujoco")
        assert worker.pid == pid and worker.alive and worker.jobs == 2
        # the second job's summary counts its own time, not the worker's age
        summary = json.loads((tmp_path / "run1" / "summary.json").read_text())
        assert summary["time_s"]["import"] < 60
        # a command a worker does not run still gets a process of its own
        job = jobs.Job(["report", "--help"], tmp_path / "logs" / "help.log").start(workers)
        assert not job.warm and job.wait(120) == 0
    finally:
        workers.close()


def _long_job_with_a_chunk(workers, out, log):
    """A 200-pick evaluate started on the warm workers, returned (with its argv without
    --out) once its first chunk is saved: a job surely mid-run."""
    argv = ["evaluate", "block", "--n", "200", "--seed", "1", *SHORT, "--chunk-size", "2"]
    job = jobs.Job([*argv, "--out", str(out)], log, out, 200, 2)
    job.start(workers)
    deadline = time.monotonic() + 240
    while not list((out / "chunks").glob("part-*.parquet")):
        assert job.running and time.monotonic() < deadline, job.log.read_text()
        time.sleep(0.2)
    return job, argv


def test_a_job_in_the_worker_is_cancelled_and_the_worker_serves_the_next(tmp_path):
    workers = warm_workers(tmp_path)
    try:
        out = tmp_path / "long"
        job, argv = _long_job_with_a_chunk(workers, out, tmp_path / "logs" / "long.log")
        assert job.warm
        # another browser tab's job while the worker is busy: a process of its own
        other = tmp_path / "other"
        beside = jobs.Job(
            ["evaluate", "block", "--n", "2", *SHORT, "--out", str(other)],
            tmp_path / "logs" / "other.log",
            other,
        ).start(workers)
        assert not beside.warm and beside.running
        job.cancel()
        job.wait(60)
        p = job.poll()
        assert p.state == "cancelled", job.log.read_text()
        assert beside.wait(300) == 0 and beside.poll().state == "complete"
        assert json.loads((out / "mjx_pick_run.json").read_text())["status"] == "interrupted"
        assert 1 <= len(list((out / "chunks").glob("part-*.parquet"))) < 100
        assert "--resume" in job.log.read_text()  # the CLI's own interrupted line
        # the same worker, still alive, resumes it: the cancel stopped the job, not it
        worker = workers.worker("mujoco")
        assert worker.alive
        again = jobs.Job([*argv, "--out", str(out), "--resume"], job.log, out, 200, 2)
        again.start(workers)
        assert again.warm and again._proc.pid == worker.pid
        again.wait(300)
        assert again.poll().state == "complete", again.log.read_text()
        assert pq.read_table(out / "results.parquet").num_rows == 200
    finally:
        workers.close()


def test_a_killed_worker_is_reported_and_a_later_job_succeeds(tmp_path):
    workers = warm_workers(tmp_path)
    try:
        job, _ = _long_job_with_a_chunk(workers, tmp_path / "killed", tmp_path / "logs" / "k.log")
        dead = workers.worker("mujoco").pid
        os.kill(dead, 9)
        job.wait(60)
        p = job.poll()
        assert p.state == "failed"
        assert "worker process that ran this job stopped (killed by signal 9" in p.message
        assert "a new one is started for the next job" in p.message
        # a new worker is started at once, and runs the next job
        worker = workers.worker("mujoco")
        assert worker.pid != dead and worker.ready.wait(180)
        out2 = tmp_path / "after"
        job = jobs.Job(
            ["evaluate", "block", "--n", "4", *SHORT, "--out", str(out2)],
            tmp_path / "logs" / "after.log",
            out2,
        ).start(workers)
        assert job.warm and job._proc.pid == worker.pid
        assert job.wait(300) == 0 and job.poll().state == "complete", job.log.read_text()
        # a worker killed while idle: the next job says so in its log, and still runs
        os.kill(worker.pid, 9)
        worker.proc.wait(30)
        job = jobs.Job(
            ["evaluate", "block", "--n", "4", *SHORT, "--out", str(tmp_path / "idle")],
            tmp_path / "logs" / "idle.log",
            tmp_path / "idle",
        ).start(workers)
        assert job.wait(300) == 0 and job.poll().state == "complete", job.log.read_text()
        assert "had stopped (killed by signal 9" in job.log.read_text()
        assert any("had stopped (killed by signal 9" in w for w in job.poll().warnings)
    finally:
        workers.close()


def test_a_job_started_right_after_its_worker_died_mid_job_does_not_hang(tmp_path):
    # the next job's start polled the dead worker's job under the workers' lock, whose
    # crash path starts the successor under the same lock: the server froze
    workers = warm_workers(tmp_path)
    try:
        out = tmp_path / "killed"
        argv = ["evaluate", "block", "--n", "200", "--seed", "1", *SHORT, "--chunk-size", "2"]
        first = jobs.Job([*argv, "--out", str(out)], tmp_path / "logs" / "k.log", out, 200, 2)
        first.start(workers)
        dead = workers.worker("mujoco")
        deadline = time.monotonic() + 240
        while not list((out / "chunks").glob("part-*.parquet")):
            assert first.running and time.monotonic() < deadline, first.log.read_text()
            time.sleep(0.2)
        os.kill(dead.pid, 9)
        dead.proc.wait(30)
        started = []
        out2 = tmp_path / "next"
        job = jobs.Job(
            ["evaluate", "block", "--n", "4", *SHORT, "--out", str(out2)],
            tmp_path / "logs" / "next.log",
            out2,
        )
        starter = threading.Thread(target=lambda: started.append(job.start(workers)))
        starter.start()
        starter.join(30)
        assert not starter.is_alive(), "starting a job hung on the dead worker"
        assert job.wait(300) == 0 and job.poll().state == "complete", job.log.read_text()
        # one successor, and it is the one the workers hold
        successor = workers.worker("mujoco")
        assert successor.pid != dead.pid and successor.alive
        assert first.poll().state == "failed"
    finally:
        workers.close()


def test_the_export_counts_the_parts_of_the_report(tmp_path):
    # the export with animations ran for a minute behind a bar with no count: its
    # progress is now the report's own count of parts, read from its log
    from mjx_pick.gui.page.job_panel import status_line

    log = tmp_path / "run-report.log"
    job = jobs.report_job(tmp_path / "run", 3, True, log)
    assert job.argv == ["report", str(tmp_path / "run"), "--n", "3"]
    assert "--no-animations" in jobs.report_job(tmp_path / "run", 3, False, log).argv
    log.write_text(
        "$ mjx-pick report run --n 3\n"
        "report:  12% 2/17 part [00:04, 0.5 part/s]\n"
        "report:  41% 7/17 part [00:21, 0.33 part/s]\n"
    )
    p = job.poll()
    assert (p.done, p.total) == (7, 17) and p.fraction == pytest.approx(7 / 17)
    assert status_line(p).startswith("running, 7/17 parts of the report")


def test_a_restarted_server_remembers_the_runs_of_its_work_folder(tmp_path):
    import fcntl

    def folder(name, status, command="evaluate", argv=None):
        out = tmp_path / name
        out.mkdir()
        manifest = {"command": command, "status": status, "started": "2026-11-24T01:00:00+00:00"}
        if status != "running":
            manifest["finished"] = "2026-11-24T01:00:12+00:00"
        (out / "mjx_pick_run.json").write_text(json.dumps(manifest))
        (out / "config.json").write_text(json.dumps({"n": 4, "chunk_size": 2}))
        (tmp_path / "logs").mkdir(exist_ok=True)
        line = f"$ mjx-pick {command} block --n 4 --out {out}\n"
        (tmp_path / "logs" / f"{name}.log").write_text(line)
        return out

    done = folder("done", "complete")
    (done / "summary.json").write_text(json.dumps({"picks_per_s": 3.5}))
    folder("stopped", "interrupted")
    folder("died", "running")  # its process ended without closing it: no lock held
    live = folder("live", "running")
    (tmp_path / "plain").mkdir()  # not a run folder
    fd = os.open(live / ".mjx_pick.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)  # a run of the previous server, still going
    os.write(fd, json.dumps({"pid": os.getpid(), "command": "evaluate"}).encode())
    try:
        runs = jobs.Runs()
        assert runs.recover(tmp_path) == 4
        got = {j.title: j for j in runs}
        assert set(got) == {"evaluate done", "evaluate stopped", "evaluate died", "evaluate live"}
        p = got["evaluate done"].poll()
        assert (p.state, p.done, p.total, p.rate) == ("complete", 4, 4, 3.5)
        assert p.elapsed_s == pytest.approx(12.0)
        assert got["evaluate done"].argv == ["evaluate", "block", "--n", "4", "--out", str(done)]
        assert got["evaluate stopped"].poll().state == "cancelled"
        assert got["evaluate died"].poll().state == "failed"
        assert got["evaluate live"].running and got["evaluate live"].poll().state == "running"
        assert runs.writing(live) is got["evaluate live"]
        assert runs.recover(tmp_path) == 0  # known already: not added twice
    finally:
        os.close(fd)
    assert not got["evaluate live"].running  # the lock released: it ended


def test_a_refused_folder_is_explained_in_the_pages_words(tmp_path):
    # the CLI's refusal of a folder of another configuration, as the page shows it: no
    # flags the page does not have, no digests, what changed by name
    import pytest

    from mjx_pick.core.config import ConfigError
    from mjx_pick.gui.forms import page_advice
    from mjx_pick.outputs.rundir import claim, config_hash, end_claims

    out = tmp_path / "run"
    first = {"seed": 0, "model": "sha256:" + "a" * 16}
    claim(out, "evaluate", config_hash(first), settings=first)
    (out / "chunks").mkdir()
    (out / "chunks" / "part-000000.parquet").write_bytes(b"x")
    end_claims("interrupted", "stopped")
    second = {"seed": 1, "model": "sha256:" + "b" * 16}
    with pytest.raises(ConfigError) as err:
        claim(out, "evaluate", config_hash(second), settings=second)
    shown = page_advice(str(err.value))
    assert "--out" not in shown and "--overwrite" not in shown and "--resume" not in shown
    assert "sha256" not in shown and "model: its content changed" in shown
    assert "seed: 0 -> 1" in shown and "run folder name" in shown
    assert "'Load this run folder's settings' in tab 3" in shown


def test_a_crashed_run_says_what_failed_and_where_its_log_is(tmp_path):
    """An exception no input check foresaw: the page names the library, the kind and the
    run's log -- never the traceback, its paths or the library's own words."""
    import trimesh

    logs = tmp_path / "logs"
    logs.mkdir()
    log = logs / "crash.log"
    library = Path(trimesh.__file__).parent / "creation.py"
    log.write_text(
        "$ mjx-pick evaluate thin.png --thickness-mm 0.00001\n"
        "Traceback (most recent call last):\n"
        f'  File "{jobs.__file__}", line 10, in main\n'
        "    run()\n"
        f'  File "{library}", line 519, in extrude_triangulation\n'
        '    raise ValueError("Height must be nonzero!")\n'
        "ValueError: Height must be nonzero!\n"
    )
    message = jobs.Job(["evaluate"], log).error_message(1)
    assert "inside trimesh (ValueError)" in message
    assert "logs/crash.log in the work folder" in message
    for raw in ("Height must be nonzero", "Traceback", str(library.parent), "line 519"):
        assert raw not in message


def test_messages_never_show_the_softwares_own_paths():
    """A path into Python's or mjx_pick's installation becomes its file name; the
    user's own paths stay as they are."""
    import trimesh

    import mjx_pick
    from mjx_pick.gui.formatting import md_text, page_text

    shipped = Path(mjx_pick.__file__).parent / "assets" / "objects" / "block.png"
    library = Path(trimesh.__file__).parent / "creation.py"
    text = f"image '{shipped}' is 0.4 mm; see {library}:519. Yours: /srv/parts/a.png."
    shown = page_text(text)
    assert shown == "image 'block.png' is 0.4 mm; see creation.py:519. Yours: /srv/parts/a.png."
    assert str(library.parent) not in md_text(text)


def test_a_runs_long_pick_point_check_shows_how_far_it_is(tmp_path):
    """Before its first chunk, an evaluate run whose pick-point search takes long shows
    the search's last progress line from its log, not a bare 'checking'."""
    out = tmp_path / "run"
    log = tmp_path / "run.log"
    note = (
        "checked 409,600 of at most 1,000,000 candidate poses: 0 of 200 feasible so far "
        "(rejected: 380,000: the object fills too little of the region between the pads)"
    )
    log.write_text(f"$ mjx-pick evaluate block --n 200\nmjx-pick: {note}\n")
    job = jobs.Job(["evaluate"], log, out, total=200, chunk=4)
    assert job.poll().message == f"checking the pick-points: {note}"
    assert jobs.Job(["sweep"], log).poll().message == f"checking the pick-points: {note}"
    with log.open("a") as fh:  # the search is over: its line is history
        fh.write("mjx-pick: simulating 3 variants\n")
    assert "checked" not in jobs.Job(["sweep"], log).poll().message


def test_height_compensation_means_the_linkages_lift_at_the_start_everywhere():
    """Tab 2's test says the fingertip height and the height compensation apart: the
    compensation is the results column's (how far a linkage starts raised), the same
    number the run's table and the robot export carry, never the fingertip height."""
    from mjx_pick.core.metrics import COLUMNS
    from mjx_pick.core.objects import load_object
    from mjx_pick.core.procedure import fingertip_height_mm
    from mjx_pick.core.scene import height_compensation_mm
    from mjx_pick.gui.one_pick import check_one_pick

    obj = load_object("block")
    for name, raised in (("robotiq-2f85-linkage", True), ("robotiq-2f85", False)):
        gripper = load_gripper(name)
        settings, errors = forms.build(forms.defaults(gripper), gripper)
        assert not errors
        checked = check_one_pick(obj, settings, 0.0, 0.0, 0.0)
        text = "\n".join(checked["lines"])
        lift = float(height_compensation_mm(settings.gripper, checked["batch"])[0])
        assert (lift > 1.0) == raised, (name, lift)
        assert (
            f"height compensation: {lift:.1f} mm ({COLUMNS['height_compensation_mm'][1]})" in text
        )
        tip = fingertip_height_mm(obj, settings.gripper, settings.grasp)
        assert f"fingertip height above the table: {tip:.1f} mm" in text
        assert checked["pose"][:8] == b"\x89PNG\r\n\x1a\n"


def test_a_studys_run_counts_its_simulations(tmp_path):
    """A sweep, compare or robust run shows how many simulations are done of how many
    (read from its log), not a bar with no count; a server that finds such a run in
    its work folder counts it the same way."""
    from mjx_pick.gui.page.job_panel import status_line

    log = tmp_path / "logs" / "sw.log"
    log.parent.mkdir()
    log.write_text(
        "$ mjx-pick sweep block --n 6 --out sw\n"
        "mjx-pick: sweep: 2 variant(s) x 6 pick-points = up to 12 simulations\n"
        "sweep: 2 variants (mujoco):  50% 6/12 sim [00:01, 3.63 sim/s]\n"
    )
    job = jobs.study_job(["sweep"], log, tmp_path / "sw")
    p = job.poll()
    assert (p.done, p.total) == (6, 12) and status_line(p).startswith("running, 6/12 simulations")
    with log.open("a") as fh:  # robust: its draws follow its pick-points, the total grows
        fh.write("robust (mujoco): 100% 6/6 sim [00:02, 3 sim/s]\n")
        fh.write("robust (mujoco):  27% 8/30 sim [00:03, 3 sim/s]\n")
    assert (job.poll().done, job.poll().total) == (8, 30)
    out = tmp_path / "sw"
    out.mkdir()
    manifest = {"command": "sweep", "status": "running", "started": "2026-11-24T01:00:00+00:00"}
    (out / "mjx_pick_run.json").write_text(json.dumps(manifest))
    (recovered,) = jobs.recovered_runs(tmp_path)
    assert recovered.poll().total == 30 and recovered.unit == "simulations"


def test_every_file_the_page_reads_resolves_inside_the_work_folder(tmp_path):
    """One check (workfolder.confined) for every file the page reads, lists or serves:
    links followed -- absolute, relative, chained, through a folder -- it lies inside
    the work folder, or it is refused by its name and where it leads; the routes built
    on it (a run folder's tree, the runs a restarted server lists, a job's progress and
    log, an upload's and a run's inputs' stored files) never read through a link out."""
    from mjx_pick.gui import workfolder
    from mjx_pick.gui.workfolder import OutsideWorkFolder, check_tree, confined

    work, away = tmp_path / "work", tmp_path / "away"
    (work / "run").mkdir(parents=True)
    away.mkdir()
    (away / "secret").write_text("secret")
    (work / "run" / "ok.txt").write_text("ok")
    links = {
        "abs": away / "secret",  # absolute
        "rel": Path("..") / ".." / "away" / "secret",  # relative, up and out
        "etc": Path("/etc/passwd"),
        "dangling": away / "none",  # does not exist: where it leads still counts
        "hop": Path("abs"),  # a chain: a link inside to a link out
        "inner": Path("ok.txt"),  # inside: allowed
        "dir": away,  # a folder
    }
    for name, target in links.items():
        (work / "run" / name).symlink_to(target)
    for name in ("abs", "rel", "etc", "dangling", "hop", "dir"):
        with pytest.raises(OutsideWorkFolder) as err:
            confined(work / "run" / name, work)
        assert str(err.value).startswith(f"run/{name}: a link that leads outside the work folder")
        with pytest.raises(OutsideWorkFolder):
            workfolder.read_bytes(f"run/{name}", work)  # relative: from the work folder
    assert workfolder.read_text(work / "run" / "inner", work) == "ok"
    assert confined(work, work) == work.resolve()
    for outside in ("/etc", "..", str(away), "run/../.."):
        assert workfolder.inside(outside, work) is None
    with pytest.raises(OutsideWorkFolder, match="run/abs"):
        check_tree(work / "run", work)
    # a folder whose link leads inside, holding a link out: found through it
    (work / "run2" / "deep").mkdir(parents=True)
    (work / "run2" / "deep" / "out").symlink_to(away / "secret")
    (work / "run3").mkdir()
    (work / "run3" / "via").symlink_to(work / "run2", target_is_directory=True)
    with pytest.raises(OutsideWorkFolder, match="run3/via/deep/out"):
        check_tree(work / "run3", work)
    (work / "run3" / "loop").symlink_to(work / "run3", target_is_directory=True)
    (work / "run2" / "deep" / "out").unlink()
    assert check_tree(work / "run3", work) == (work / "run3").resolve()  # loops end

    # the runs a restarted server lists: a run folder reached through a link out is not
    manifest = {"command": "evaluate", "status": "complete", "started": "2026-11-24T01:00:00"}
    (away / "run-out").mkdir()
    (away / "run-out" / "mjx_pick_run.json").write_text(json.dumps(manifest))
    (work / "run-out").symlink_to(away / "run-out", target_is_directory=True)
    (work / "run-in").mkdir()
    (work / "run-in" / "mjx_pick_run.json").symlink_to(away / "run-out" / "mjx_pick_run.json")
    folders, left_out = workfolder.run_folders(work)
    assert work / "run-out" not in folders and any(s.startswith("run-out: ") for s in left_out)
    assert workfolder.manifest(work / "run-in", work) is None  # its manifest leads out
    assert jobs.recovered_runs(work) == []

    # a job's progress and log: never read through a link out
    (work / "logs").mkdir()
    (work / "logs" / "j.log").symlink_to(away / "secret")
    (work / "j").mkdir()
    (work / "j" / "config.json").symlink_to(away / "config.json")
    (away / "config.json").write_text(json.dumps({"n": 99, "chunk_size": 1}))
    job = jobs.Job(["evaluate"], work / "logs" / "j.log", work / "j", 4, 2)
    job._proc = jobs.FolderRun(work / "j", work)
    assert job.poll().total == 4 and "secret" not in job.error_message(1)

    # stored files: an upload or a run's settings never read or written through a link
    uploads = work / "inputs" / "uploads"
    uploads.mkdir(parents=True)
    (uploads / "part.png").symlink_to(away / "secret")
    stored = save_upload(b"secret", "part.png", uploads, work)
    assert stored == uploads / "part-2.png" and stored.read_bytes() == b"secret"
    (work / "inputs" / "elsewhere").symlink_to(away, target_is_directory=True)
    with pytest.raises(OutsideWorkFolder):
        save_upload(b"x", "a.png", work / "inputs" / "elsewhere", work)
    settings, _ = forms.build(values(), load_gripper("robotiq-2f85"))
    (work / "inputs" / "r").mkdir()
    (work / "inputs" / "r" / "grasp.toml").symlink_to(away / "grasp.toml")
    paths = forms.write_inputs(settings, work / "inputs" / "r", work)
    assert paths["grasp"] == work / "inputs" / "r-2" / "grasp.toml"
    assert not (away / "grasp.toml").exists()
    paths = forms.write_inputs(settings, work / "inputs" / "elsewhere", work)
    assert paths["grasp"].parent == work / "inputs" / "elsewhere-2"


def test_the_sweeps_picture_names_its_parameter_in_the_pages_words(block, tmp_path, monkeypatch):
    """The page draws a sweep's picture with each parameter's axis in words
    (forms.sweep_labels), not the key its command took (contact.pad_friction)."""
    import matplotlib.axes

    import mjx_pick as mp
    from mjx_pick.core.procedure import GraspConfig
    from mjx_pick.gui import views
    from mjx_pick.studies.sweeps import ParamSpec

    grasp = GraspConfig(close_timeout_s=1.0, lift_height_mm=5.0, hold_s=0.05)
    out = tmp_path / "work" / "sweep"
    mp.sweep(
        block,
        [ParamSpec.parse("contact.pad_friction=0.5,0.8")],
        mp.Settings(grasp=grasp),
        n=1,
        out=out,
        backend="mujoco",
    )
    said = []
    real = matplotlib.axes.Axes.set_xlabel
    monkeypatch.setattr(
        matplotlib.axes.Axes,
        "set_xlabel",
        lambda ax, label, *a, **k: said.append(label) or real(ax, label, *a, **k),
    )
    png = views.sweep_png(out, tmp_path / "work", forms.sweep_labels())
    assert png.startswith(b"\x89PNG") and set(said) == {"pad friction"}, said


def test_two_runs_never_write_one_folder_at_once(tmp_path):
    """A run's folder taken by a running run of this server (any browser tab's) is
    refused as the second starts -- said with whose run it is -- also a report into a
    run's folder; a run that ended frees it."""

    class Running:  # a process that runs until told
        pid, code = 1, None

        def poll(self):
            return self.code

    runs = jobs.Runs()
    out = tmp_path / "twin"
    first = jobs.Job(["evaluate", "--out", str(out)], tmp_path / "logs" / "twin.log", out)
    first.title, first._proc = "evaluate twin", Running()
    runs.add(first, "tab-a")
    second = jobs.Job(["evaluate"], tmp_path / "logs" / "twin.log", tmp_path / "." / "twin")
    said = runs.taken(second, "tab-b")
    assert said.startswith("twin: 'evaluate twin' (another browser tab's) is writing"), said
    assert "this browser tab's" in runs.taken(second, "tab-a")
    report = jobs.report_job(out, 3, False, tmp_path / "logs" / "twin-report.log")
    assert "is writing this folder now" in runs.taken(report, "tab-b")
    assert runs.taken(jobs.Job(["evaluate"], tmp_path / "x.log", tmp_path / "other"), None) == ""
    first._proc.code = 0  # it ended: the folder is free (the CLI says what it holds)
    assert runs.taken(second, "tab-b") == ""


def test_a_run_refused_as_long_is_the_pages_own_estimate_and_starts_again_with_yes(tmp_path):
    """The CLI refuses an evaluate of a million pick-points unasked (studies.duration);
    the page reads that refusal (and would have said the same words itself: one
    estimate), and starts the same run again with --yes, its first log gone."""
    out = tmp_path / "long"
    argv = ["evaluate", "block", "--n", "1000000", "--backend", "mujoco", "--out", str(out)]
    job = jobs.Job(argv, tmp_path / "logs" / "long.log", out, 1_000_000, 1000)
    job.start().wait(120)
    refused = job.refused_as_long()
    assert refused == jobs.long_run("evaluate", "this evaluate", "mujoco", n=1_000_000)
    assert "would take about" in refused and not out.exists()  # before any work
    assert forms.page_words(refused).endswith("start it anyway, or make it smaller")
    again = job.again("--yes")
    assert again.argv == [*argv, "--yes"] and again.out == out
    assert (again.total, again.chunk, again.asked_log) == (1_000_000, 1000, job.log)
    assert again.refused_as_long() == ""  # not started yet, and never with --yes
    job.discard_log()
    assert not job.log.exists()


def test_a_trials_zip_is_checked_member_by_member_before_anything_is_written(tmp_path):
    """uploads.store_trials: a member that would leave its folder (absolute, '..', a
    drive), a link, none or two TRIALS.csv files, too many files: refused naming it,
    nothing written; a good zip unpacked beside an earlier one, never over it."""
    import stat
    import zipfile

    from mjx_pick.gui.uploads import store_trials

    header = b"object,mass_g,gripper,grasp_pose,success,trial\n"

    def zipped(members: dict, link: str | None = None) -> bytes:
        path = tmp_path / "t.zip"
        with zipfile.ZipFile(path, "w") as z:
            for name, data in members.items():
                z.writestr(name, data)
            if link is not None:
                info = zipfile.ZipInfo(link)
                info.external_attr = (stat.S_IFLNK | 0o777) << 16
                z.writestr(info, "/etc/passwd")
        return path.read_bytes()

    work = tmp_path / "work"
    folder = work / "inputs" / "trials"
    good = {"set/TRIALS.csv": header, "set/cube.obj": b"v 0 0 0\n"}
    for members, link, said in (
        ({**good, "/abs.obj": b"x"}, None, "'/abs.obj' would be written outside"),
        ({**good, "set/../../up.obj": b"x"}, None, "'set/../../up.obj' would be written"),
        ({**good, "C:/x.obj": b"x"}, None, "'C:/x.obj' would be written outside"),
        (good, "set/mesh.obj", "'set/mesh.obj' is a link"),
        ({"set/cube.obj": b"v"}, None, "holds 0 TRIALS.csv files (none)"),
        ({**good, "b.csv": header}, None, "holds 2 TRIALS.csv files"),
        ({f"f{k}.obj": b"" for k in range(2001)} | good, None, "2,003 files"),
    ):
        with pytest.raises(ConfigError, match=re.escape(said)):
            store_trials(zipped(members, link), "t.zip", folder, work)
        assert not folder.exists() or not any(folder.iterdir())
    with pytest.raises(ConfigError, match="cannot be read as a zip file"):
        store_trials(b"not a zip", "t.zip", folder, work)
    first = store_trials(zipped(good), "t.zip", folder, work)
    second = store_trials(zipped(good), "t.zip", folder, work)
    assert first == folder / "t" / "set" / "TRIALS.csv" and first.read_bytes() == header
    assert second == folder / "t-2" / "set" / "TRIALS.csv"


def test_a_files_own_words_stay_and_the_programs_become_the_pages():
    """forms.file_words: a file's columns and keys kept, a CLI flag said as the page's
    control (a file never holds one)."""
    said = forms.file_words(
        "g.csv line 3, column depth_mm: 'x' is not a number; give it (--depth-mm)"
    )
    assert said == "g.csv line 3, column depth_mm: 'x' is not a number; give it"
    assert "grasp depth (mm) (tab 3)" in forms.file_words("use --depth-mm here")


def test_the_page_never_counts_gpus_itself(monkeypatch):
    """Where an NVIDIA driver is loaded, the page's estimate of a GPU backend's (or
    'auto''s) run is left to the run's own process -- counting GPUs starts Warp's CUDA
    runtime, which the server never does; the CLI refuses a long one and the page asks
    then. A CPU backend is estimated in the page as before."""
    from mjx_pick.engine import devices, registry

    monkeypatch.setattr(devices, "nvidia_driver_present", lambda: True)
    monkeypatch.setattr(devices, "nvidia_gpu_count", lambda: pytest.fail("GPUs counted"))
    gpu = [n for n, e in registry.ENTRIES.items() if e.device is registry.Device.NVIDIA_GPU]
    for backend in [registry.AUTO, *gpu]:
        assert jobs.long_run("evaluate", "this evaluate", backend, n=10**8) == ""
    assert "would take" in jobs.long_run("evaluate", "this evaluate", "mujoco", n=10**8)
