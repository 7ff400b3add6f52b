"""Second routes to a wrong answer, closed: each test drives the installed ``mjx-pick``
command the way a user would and checks that nothing is lost, mismatched or silently
wrong (folders replaced, reruns merged, inputs out of range)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

MJX_PICK = shutil.which("mjx-pick") or f"{sys.executable} -m mjx_pick.cli"
FAST = ["--backend", "mujoco", "--no-progress", "--lift-height-mm", "5", "--hold-s", "0.05"]


def cli(*argv, check: bool | None = None, timeout: float = 300, cwd=None, **kw):
    """Run the installed command; check=True: it must succeed, False: it must fail
    (refused with a message, never a traceback). tests/test_third_routes.py's too."""
    cmd = MJX_PICK.split() + [str(a) for a in argv]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd, **kw)
    if check is True:
        assert res.returncode == 0, res.stderr[-3000:]
    if check is False:
        assert res.returncode != 0, res.stdout[-2000:]
        assert "Traceback" not in res.stderr, res.stderr[-3000:]
    return res


def chunk_files(out: Path) -> list[Path]:
    return sorted((out / "chunks").rglob("part-*.parquet"))


def killed_mid_run(out: Path, *extra) -> int:
    """An evaluate run killed outright (SIGKILL) once some of its chunks are saved; the
    number of chunks it left."""
    cmd = MJX_PICK.split() + ["evaluate", "block", "--n", "96", "--batch-size", "8"]
    cmd += ["--chunk-size", "8", "--out", str(out), *FAST, *map(str, extra)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while len(chunk_files(out)) < 2 and time.monotonic() < deadline:
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    n = len(chunk_files(out))
    assert n >= 2
    return n


def test_a_killed_run_keeps_its_chunks_from_a_rerun_with_other_settings(tmp_path):
    out = tmp_path / "run"
    n = killed_mid_run(out)
    res = cli("evaluate", "block", "--n", "96", "--seed", "1", "--out", out, *FAST, check=False)
    assert "finished chunk" in res.stderr and "seed: 0 -> 1" in res.stderr
    assert "--resume" in res.stderr and "--overwrite" in res.stderr
    assert len(chunk_files(out)) == n  # nothing deleted


def test_a_resume_under_other_package_versions_is_refused(tmp_path):
    out = tmp_path / "run"
    n = killed_mid_run(out)
    # the folder as another MuJoCo would have left it: its record names that version
    config = json.loads((out / "config.json").read_text())
    config["versions"]["mujoco"] = "3.1.0"
    (out / "config.json").write_text(json.dumps(config))
    manifest = json.loads((out / "mjx_pick_run.json").read_text())
    manifest.pop("versions", None)  # as a folder written before versions were recorded
    (out / "mjx_pick_run.json").write_text(json.dumps(manifest))
    argv = ["evaluate", "block", "--n", "96", "--batch-size", "8", "--chunk-size", "8"]
    res = cli(*argv, "--out", out, "--resume", *FAST, check=False)
    assert "mujoco" in res.stderr and "3.1.0" in res.stderr
    assert len(chunk_files(out)) == n
    assert json.loads((out / "config.json").read_text())["versions"]["mujoco"] == "3.1.0"


@pytest.fixture(scope="module")
def rg2_run(tmp_path_factory) -> Path:
    """A finished evaluate run on the RG2, hold 0.2 s (not the defaults)."""
    out = tmp_path_factory.mktemp("rg2") / "run"
    argv = ["evaluate", "block", "--gripper", "onrobot-rg2", "--n", "12", "--out", out]
    cli(*argv, *FAST[:-1], "0.2", "--traces", "0", check=True)
    return out


def test_robust_on_a_run_simulates_with_the_runs_settings(rg2_run, tmp_path):
    out = rg2_run
    res = cli(
        "robust",
        "block",
        "--results",
        out,
        "--out",
        out,
        "--top-k",
        "2",
        "--m",
        "2",
        "--backend",
        "mujoco",
        "--no-progress",
        check=True,
    )
    record = json.loads((out / "run-robust.json").read_text())
    assert record["config"]["settings"]["gripper"]["name"] == "onrobot-rg2"
    assert record["config"]["settings"]["grasp"]["hold_s"] == 0.2
    assert "robust" in res.stdout
    # settings the user gives that differ from the run's: refused, naming them
    res = cli(
        "robust",
        "block",
        "--results",
        out,
        "--top-k",
        "2",
        "--m",
        "2",
        "--gripper",
        "robotiq-2f85",
        "--backend",
        "mujoco",
        "--no-progress",
        check=False,
    )
    assert "onrobot-rg2" in res.stderr and "robotiq-2f85" in res.stderr


def test_a_second_robust_with_other_settings_does_not_replace_the_first(rg2_run):
    out = rg2_run
    argv = ["robust", "block", "--results", out, "--out", out, "--top-k", "2"]
    cli(*argv, "--m", "3", "--overwrite", "--backend", "mujoco", "--no-progress", check=True)
    before = (out / "robustness.parquet").read_bytes()
    res = cli(*argv, "--m", "4", "--backend", "mujoco", "--no-progress", check=False)
    assert "m: 3 -> 4" in res.stderr and "--overwrite" in res.stderr
    assert (out / "robustness.parquet").read_bytes() == before
    cli(*argv, "--m", "4", "--overwrite", "--backend", "mujoco", "--no-progress", check=True)
    assert (out / "results.parquet").is_file()  # evaluate's own files stay


# ---------------------------------------------------------------- numbers: one rule each


@pytest.mark.parametrize(
    "argv, said",
    [
        (["evaluate", "block", "--seed", "-1"], "--seed = -1 is out of range"),
        (["evaluate", "block", "--traces", "-1"], "--traces = -1 is out of range"),
        (["evaluate", "block", "--n", "2.5"], "--n = 2.5 must be a whole number"),
        (["evaluate", "block", "--n", "nan"], "--n = nan must be a finite number"),
        (["evaluate", "block", "--mass-g", "5", "--density-kg-m3", "900"], "give one"),
        (["evaluate", "block", "--density-kg-m3", "900"], "density_kg_m3 does not apply"),
        (["evaluate", "block", "--stability-um", "inf"], "--stability-um = inf must be a finite"),
        (["robust", "block", "--m", "0"], "--m = 0 is out of range"),
        (["sweep", "block", "--param", "contact.pad_friction=0.1:1:100000"], "N = 100000"),
        (["sweep", "block", "--param", "contact.pad_friction=0.1,nan"], "must be a finite"),
        (["design", "block", "--bound", "stroke_mm=10:28"], "none of the 12 variants"),
        (["sweep", "block", "--param", "gripper.stroke_mm=20,85"], "variant gripper.stroke_mm=20"),
    ],
)
def test_a_number_out_of_its_range_is_refused_before_work(argv, said, tmp_path):
    res = cli(*argv, "--out", tmp_path / "never", "--backend", "mujoco", check=False)
    assert said in res.stderr
    assert not (tmp_path / "never").exists()


def test_every_bad_number_of_a_command_line_is_named_at_once():
    res = cli("evaluate", "block", "--seed", "-1", "--traces", "0.5", "--n", "0", check=False)
    assert "3 problems" in res.stderr
    for flag in ("--seed", "--traces", "--n"):
        assert f"{flag} = " in res.stderr


def test_a_picks_file_with_an_absurd_or_repeated_pose_is_refused(tmp_path):
    huge, turn = tmp_path / "huge.csv", tmp_path / "turn.csv"
    huge.write_text("x_mm,y_mm,yaw_deg\n0,0,1e300\n")
    turn.write_text("x_mm,y_mm,yaw_deg\n0,0,10\n1,0,0\n0,0,370\n")
    res = cli("evaluate", "block", "--picks", huge, "--backend", "mujoco", check=False)
    assert "line 2: yaw_deg = 1e+300 is out of range: allowed -360 <= yaw_deg <= 720" in res.stderr
    res = cli("evaluate", "block", "--picks", turn, "--backend", "mujoco", check=False)
    assert "line 4 repeats line 2" in res.stderr


def test_report_on_a_damaged_results_table_says_so(tmp_path):
    import pyarrow.parquet as pq

    run = tmp_path / "run"
    cli("evaluate", "block", "--n", "4", "--out", run, "--traces", "0", *FAST, check=True)
    table = pq.read_table(run / "results.parquet")
    pq.write_table(table.drop(["score"]), run / "results.parquet")
    res = cli("report", run, "--no-animations", check=False)
    assert "has no score column" in res.stderr
    pq.write_table(table.slice(0, 0), run / "results.parquet")
    res = cli("report", run, "--no-animations", check=False)
    assert "has no pick-points" in res.stderr


def test_a_fit_without_intervals_still_says_what_it_could_not_check(tmp_path):
    # outcomes without their record (no TOML beside the CSV), a fit pressed on its bound
    # and --no-identify: each said on the terminal and in the report, never a bare value
    shipped = Path(__file__).resolve().parents[1] / "mjx_pick/assets/outcomes/block_1kg_rg2.csv"
    rows = shipped.read_text().splitlines()
    csv = tmp_path / "mine.csv"
    csv.write_text("\n".join(rows[:1] + rows[4:8]) + "\n")
    out = tmp_path / "cal"
    # a search that starts on its lower bound and takes no step: its optimum is on it
    argv = ["calibrate", csv, "block", "--mass-g", "1000", "--gripper", "onrobot-rg2"]
    argv += ["--pad-friction", "0.3", "--bounds", "pad_friction=0.3:0.9"]
    argv += ["--estimator", "random", "--steps", "0"]
    argv += ["--no-identify", "--backend", "mujoco", "--no-progress", "--out", out]
    res = cli(*argv, check=True)
    assert "note: the outcomes have no record" in res.stderr
    assert "fit at its lower bound 0.3: NOT identified" in res.stdout
    toml = (out / "contact.toml").read_text()
    assert 'not_identified = ["pad_friction"]' in toml
    report = (out / "report.md").read_text()
    assert "kept at its starting value" in report and "lower bound" in report
    assert "no record of what they were measured with" in report


def _box_stl(path: Path, flip: int | None = None) -> Path:
    """A 30 x 20 x 15 mm box as a binary STL (9.0 g at 1000 kg/m^3); flip: one triangle
    wound the wrong way (a closed surface whose volume is then wrong)."""
    import trimesh

    box = trimesh.creation.box([30.0, 20.0, 15.0])
    faces = box.faces.copy()
    if flip is not None:
        faces[flip] = faces[flip][::-1]
    trimesh.Trimesh(box.vertices, faces, process=False).export(path)
    return path


def test_a_mesh_repaired_on_import_is_right_or_refused_and_always_said(tmp_path):
    stl = _box_stl(tmp_path / "flipped.stl", flip=0)
    out = tmp_path / "picks"
    argv = ["picks", stl, "--unit", "mm", "--density-kg-m3", "1000", "--n", "2", "--out", out]
    res = cli(*argv, "--no-cache", check=True)
    assert "mesh flipped.stl repaired: triangles turned to face outward" in res.stderr
    assert "mass 9 g +- 0 g at 1000 kg/m^3" in res.stderr
    obj = json.loads((out / "run.json").read_text())["config"]["object"]
    assert obj["mass_g"] == pytest.approx(9.0, rel=1e-6)  # not 4.5 g, nor shifted
    assert obj["bounds_mm"] == pytest.approx([-15.0, -10.0, 15.0, 10.0], abs=1e-6)
    assert obj["repair"]["turned"] and obj["repair"]["volume_doubt_mm3"] == 0


def test_a_mesh_file_too_big_or_cut_short_is_refused_from_its_header(tmp_path):
    whole = _box_stl(tmp_path / "box.stl").read_bytes()
    cut = tmp_path / "cut.stl"
    cut.write_bytes(whole[:300])
    big = tmp_path / "big.stl"
    with big.open("wb") as fh:  # 3.9 million triangles (a sparse file: no disk used)
        fh.write(whole[:80] + (3_900_000).to_bytes(4, "little"))
        fh.truncate(84 + 50 * 3_900_000)
    for path, said in ((cut, "is cut short"), (big, "has 3900000 triangles")):
        res = cli(
            "picks",
            path,
            "--unit",
            "mm",
            "--mass-g",
            "9",
            "--n",
            "2",
            "--out",
            tmp_path / "never",
            check=False,
            timeout=60,
        )
        assert said in res.stderr
    assert not (tmp_path / "never").exists()


def test_resume_of_a_folder_that_does_not_exist_is_refused(tmp_path):
    res = cli(
        "evaluate", "block", "--n", "4", "--out", tmp_path / "typo", "--resume", *FAST, check=False
    )
    assert "does not exist, so there is no run to continue" in res.stderr
    assert not (tmp_path / "typo").exists()


def test_a_part_that_fits_only_at_its_corners_is_said_to(tmp_path):
    # a 120 mm square on the 2F-85's 85 mm stroke: a few poses take a corner between
    # the pads; such pick-points are drawn, and the rarity is said (not silently ranked)
    import cv2
    import numpy as np

    img = np.full((1300, 1300, 3), 255, np.uint8)
    img[50:1250, 50:1250] = 0
    square = tmp_path / "square.png"
    cv2.imwrite(str(square), img)
    argv = ["picks", square, "--px-per-mm", "10", "--thickness-mm", "20", "--mass-g", "200"]
    res = cli(*argv, "--n", "2", "--out", tmp_path / "p", check=True)
    assert "barely fits between the pads" in res.stderr
