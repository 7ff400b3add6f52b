"""The README's examples run as written, so that a wrong example fails the build.

Code blocks marked ``<!-- ci:example SUBS -->`` are run: a bash block one command at a
time through the CLI's ``main`` (in this process: one import, shared compiles), the
Python block in a child process with no display and no MUJOCO_GL (as a user's headless
script). SUBS are the only changes, declared in the README beside the block:
``--flag=V`` sets that flag's value in bash lines that give it, ``CMD:--flag=V`` gives it
to every ``mjx-pick CMD`` line (``report:--anim-every=32``: fewer animation frames, the
same rendering), ``name=V`` sets ``name=<number>`` in Python (small n, few steps, few
frames: the examples as written take minutes on 2 cores, most of it rendering).

Not run here: `mjx-pick gui` and `view` (they need a browser or a display: their own
tests cover them), `--ray` lines (a cluster: tests/test_cluster.py), the YCB mesh lines
(convex decomposition takes most of a minute each on 2 cores: tests/test_mesh_import.py
imports those meshes), the GPU install
line, and the blocks not marked (the Quick start lines are `.ci/run`'s; the Studies,
trials and Ray blocks take minutes even small: their commands are tested in
tests/test_studies.py, test_calibrate.py, test_trials.py and test_cluster.py).
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from mjx_pick.cli import main

ROOT = Path(__file__).resolve().parents[1]
MARK = re.compile(r"<!-- ci:example(?P<subs>[^>]*)-->\s*```(?P<lang>\w+)\n(?P<code>.*?)```", re.S)
SKIP = ("mjx-pick view", "mjx-pick gui", "--ray", ".stl ")


def examples(lang: str) -> list[tuple[str, dict]]:
    found = []
    for m in MARK.finditer((ROOT / "README.md").read_text()):
        if m["lang"] == lang:
            subs = dict(s.split("=", 1) for s in m["subs"].split())
            found.append((m["code"], subs))
    return found


def bash_commands(code: str, subs: dict) -> list[list[str]]:
    """Each `mjx-pick ...` command of a bash block (&& splits a line), with subs."""
    out = []
    for line in code.splitlines():
        words = shlex.split(line, comments=True)
        while words:
            cut = words.index("&&") if "&&" in words else len(words)
            cmd, words = words[:cut], words[cut + 1 :]
            assert cmd[0] == "mjx-pick", line
            text = " ".join(cmd)
            if any(s in text for s in SKIP):
                continue
            for key, value in subs.items():
                command, _, flag = key.rpartition(":")
                if flag in cmd:
                    if not command or cmd[1] == command:
                        cmd[cmd.index(flag) + 1] = value
                elif command and cmd[1] == command:
                    cmd += [flag, value]
            out.append(cmd[1:])
    return out


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    (tmp_path / "mjx_pick").symlink_to(ROOT / "mjx_pick")  # the README's asset paths
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_readme_marks_its_examples():
    assert len(examples("bash")) >= 1 and len(examples("python")) == 1


def test_subs_set_given_flags_and_add_a_commands_own():
    subs = {"--n": "6", "report:--anim-every": "32"}
    code = "mjx-pick evaluate x --n 1000 && mjx-pick report runs/do\nmjx-pick report r --n 3\n"
    assert bash_commands(code, subs) == [
        ["evaluate", "x", "--n", "6"],
        ["report", "runs/do", "--anim-every", "32"],
        ["report", "r", "--n", "6", "--anim-every", "32"],
    ]


def test_readme_bash_examples(workdir, capsys):
    for code, subs in examples("bash"):
        for argv in bash_commands(code, subs):
            rc = main(argv)
            err = capsys.readouterr().err
            assert rc == 0, f"mjx-pick {' '.join(argv)}: {err[-2000:]}"


def test_readme_python_example(workdir):
    ((code, subs),) = examples("python")
    for name, value in subs.items():
        code, k = re.subn(rf"\b{name}=\d+", f"{name}={value}", code)
        assert k, f"the README's Python example sets no {name}="
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=workdir, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert (workdir / "runs" / "do" / "report.html").is_file() or any(
        (workdir / "runs" / "do").glob("*.html")
    )
