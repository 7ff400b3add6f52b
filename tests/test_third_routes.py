"""Nothing silent, third routes: each class of wrong answer closed once for every route
-- one reader of a user's text files, user text escaped wherever it is written, only a
run's own recorded files ever removed, nothing written by a refused command, no number
silently changed, an estimate before a long job. Each test drives the installed
``mjx-pick`` command the way a user would."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

MJX_PICK = shutil.which("mjx-pick") or f"{sys.executable} -m mjx_pick.cli"
FAST = ["--backend", "mujoco", "--no-progress", "--lift-height-mm", "5", "--hold-s", "0.05"]
SHIPPED = Path(__file__).resolve().parents[1] / "mjx_pick" / "assets"


def cli(*argv, check: bool | None = None, timeout: float = 300, cwd=None, **kw):
    """Run the installed command; check=True: it must succeed, False: it must fail
    (refused with a message, never a traceback)."""
    cmd = MJX_PICK.split() + [str(a) for a in argv]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd, **kw)
    if check is True:
        assert res.returncode == 0, res.stderr[-3000:]
    if check is False:
        assert res.returncode != 0, res.stdout[-2000:]
        assert "Traceback" not in res.stderr, res.stderr[-3000:]
    return res


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
    res = cli("evaluate", "block", flag, f, "--n", "2", "--out", tmp_path / "never", *FAST)
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
