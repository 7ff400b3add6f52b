"""Probe the second routes of issue 49 with values of its own, through the installed CLI.

Each probe is one hostile command line (or a folder made hostile first) and what a right
answer is. It is classified as

* refused: the command exits with one ``mjx-pick: error:`` line naming the input, no
  traceback, and leaves no output folder it did not have (or the one it had, unchanged);
* handled: the command succeeds and its output passes the probe's check;
* wrong: anything else (a traceback, a silent acceptance, a lost or changed folder).

Run from the repository root with mjx_pick installed:

    python benchmarks/probes/second_routes.py [--out runs/probes] [--only NAME]

It prints one line per probe and the counts per case family, and writes probes.csv.
A probe takes 5-60 s on a 2-core CPU (the killed runs the longest).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

MJX = [
    shutil.which("mjx-pick") or sys.executable,
    *([] if shutil.which("mjx-pick") else ["-m", "mjx_pick.cli"]),
]
FAST = ["--backend", "mujoco", "--no-progress", "--lift-height-mm", "5", "--hold-s", "0.05"]


def run(*argv, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([*MJX, *map(str, argv)], capture_output=True, text=True, timeout=timeout)


def verdict(
    res,
    *,
    refused_with: str | None = None,
    ok: Callable[[], bool] | None = None,
    folder: Path | None = None,
    before: dict | None = None,
) -> tuple[str, str]:
    """Classify one command's result (see the module docstring)."""
    if "Traceback" in res.stderr:
        return "wrong", "traceback: " + res.stderr.strip().splitlines()[-1][:160]
    if refused_with is not None:
        said = res.returncode != 0 and refused_with in res.stderr
        kept = True
        if folder is not None:
            kept = snapshot(folder) == before if before is not None else not folder.exists()
        if said and kept:
            return "refused", res.stderr.strip().splitlines()[-1][:160]
        why = "accepted" if res.returncode == 0 else "other error"
        return "wrong", f"{why}{'' if kept else ', folder changed'}: {res.stderr.strip()[-160:]}"
    if res.returncode == 0 and (ok is None or ok()):
        return "handled", (res.stderr.strip().splitlines() or [""])[-1][:160]
    return "wrong", f"exit {res.returncode}: {res.stderr.strip()[-160:]}"


def snapshot(folder: Path) -> dict:
    """Every file under folder with its size and modification time."""
    if not folder.exists():
        return {}
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
        if p.is_file() and not p.name.startswith(".")
    }


def killed_run(out: Path, *extra) -> int:
    """An evaluate run SIGKILLed once two chunks are saved; the chunks it left."""
    cmd = [*MJX, "evaluate", "block", "--n", "96", "--batch-size", "8", "--chunk-size", "8"]
    proc = subprocess.Popen(
        [*cmd, "--out", str(out), *FAST, *map(str, extra)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 600
    while len(list((out / "chunks").glob("part-*"))) < 2 and time.monotonic() < deadline:
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    return len(list((out / "chunks").glob("part-*")))


def box_stl(path: Path, flip: int | None = None, drop: int | None = None, shape="box") -> Path:
    import numpy as np
    import trimesh

    mesh = (
        trimesh.creation.box([30.0, 20.0, 15.0])
        if shape == "box"
        else trimesh.creation.cylinder(radius=12.0, height=25.0, sections=24)
    )
    faces = mesh.faces.copy()
    if flip is not None:
        faces[flip] = faces[flip][::-1]
    if drop is not None:
        faces = np.delete(faces, drop, axis=0)
    trimesh.Trimesh(mesh.vertices, faces, process=False).export(path)
    return path


class ProbeList(list):
    """(family, name, probe) rows, each added by decorating its probe: ``@add(family,
    name)`` where ``add = probes.add``."""

    def add(self, family: str, name: str):
        def wrap(fn):
            self.append((family, name, fn))
            return fn

        return wrap


def probes(tmp: Path) -> list[tuple[str, str, Callable[[], tuple[str, str]]]]:
    """(family, name, probe) for each probe; each probe returns its (class, note)."""
    out = ProbeList()
    add = out.add

    # 1: a killed run's chunks and a rerun with other settings
    for i, change in enumerate((["--seed", "7"], ["--grip-force-n", "30"], ["--n", "80"])):

        @add("1 killed run rerun", " ".join(change))
        def _(change=change, i=i):
            folder = tmp / f"killed{i}"
            killed_run(folder)
            before = snapshot(folder)
            argv = ["evaluate", "block", "--n", "96", "--batch-size", "8", "--chunk-size", "8"]
            argv = argv if change[0] != "--n" else argv[:2] + argv[4:]
            res = run(*argv, *change, "--out", folder, *FAST)
            return verdict(res, refused_with="finished chunks", folder=folder, before=before)

    # 2, 5: robust into an evaluate folder
    ev = tmp / "ev_rg2"

    def ev_rg2():
        if not (ev / "results.parquet").is_file():
            run(
                "evaluate",
                "block",
                "--gripper",
                "onrobot-rg2",
                "--n",
                "12",
                "--out",
                ev,
                "--traces",
                "0",
                *FAST[:-1],
                "0.3",
            )

    for i, (first, second) in enumerate(
        ((["--sigma-xy-mm", "1"], ["--sigma-xy-mm", "1.5"]), (["--top-k", "2"], ["--top-k", "3"]))
    ):

        @add("2 second robust", f"{first} then {second}")
        def _(first=first, second=second, i=i):
            ev_rg2()
            base = ["robust", "block", "--results", ev, "--out", ev, "--m", "2", "--top-k", "2"]
            base += ["--backend", "mujoco", "--no-progress"]
            run(*base, *first, "--overwrite")
            before = snapshot(ev)
            res = run(*base, *second)
            return verdict(res, refused_with="another configuration", folder=ev, before=before)

    @add("5 robust on a run", "the run's RG2 and hold 0.3 s")
    def _():
        ev_rg2()
        res = run(
            "robust",
            "block",
            "--results",
            ev,
            "--out",
            ev,
            "--m",
            "2",
            "--top-k",
            "1",
            "--backend",
            "mujoco",
            "--no-progress",
            "--overwrite",
        )

        def ok():
            s = json.loads((ev / "run-robust.json").read_text())["config"]["settings"]
            return s["gripper"]["name"] == "onrobot-rg2" and s["grasp"]["hold_s"] == 0.3

        return verdict(res, ok=ok)

    @add("5 robust on a run", "another gripper given")
    def _():
        ev_rg2()
        before = snapshot(ev)
        res = run(
            "robust",
            "block",
            "--results",
            ev,
            "--m",
            "2",
            "--top-k",
            "1",
            "--gripper",
            "franka-hand",
            "--backend",
            "mujoco",
            "--no-progress",
        )
        return verdict(res, refused_with="franka-hand", folder=ev, before=before)

    # 6: a resume under other package versions
    for pkg in ("numpy", "mjx-pick"):

        @add("6 resume, other versions", pkg)
        def _(pkg=pkg):
            folder = tmp / f"versions-{pkg}"
            killed_run(folder)
            config = json.loads((folder / "config.json").read_text())
            config["versions"][pkg] = "0.0.1"
            (folder / "config.json").write_text(json.dumps(config))
            m = json.loads((folder / "mjx_pick_run.json").read_text())
            m.get("versions", {}).update({pkg: "0.0.1"})
            (folder / "mjx_pick_run.json").write_text(json.dumps(m))
            before = snapshot(folder)
            argv = ["evaluate", "block", "--n", "96", "--batch-size", "8", "--chunk-size", "8"]
            res = run(*argv, "--out", folder, "--resume", *FAST)
            return verdict(res, refused_with="0.0.1", folder=folder, before=before)

    # 3: meshes that are no closed solid
    for name, kw in (
        ("cylinder, a triangle turned", {"flip": 5, "shape": "cyl"}),
        ("box, a triangle missing", {"drop": 7}),
        ("box, two triangles turned", {"flip": 3}),
    ):

        @add("3 mesh repaired", name)
        def _(name=name, kw=kw):
            import math

            stl = box_stl(tmp / f"{name.replace(' ', '_').replace(',', '')}.stl", **kw)
            folder = tmp / f"picks-{stl.stem}"
            res = run(
                "picks",
                stl,
                "--unit",
                "mm",
                "--density-kg-m3",
                "1000",
                "--n",
                "2",
                "--out",
                folder,
                "--no-cache",
            )
            true_g = 9.0 if kw.get("shape") != "cyl" else None
            if true_g is None:
                import trimesh

                true_g = (
                    trimesh.creation.cylinder(radius=12.0, height=25.0, sections=24).volume / 1000
                )

            def ok():
                mass = json.loads((folder / "run.json").read_text())["config"]["object"]["mass_g"]
                return math.isclose(mass, true_g, rel_tol=1e-3) and "closed solid" in res.stderr

            return verdict(res, ok=ok)

    # 4: pick files
    for name, rows in (
        ("yaw 1e308", "0,0,1e308"),
        ("x 1e6", "1e6,0,0"),
        ("yaw nan", "0,0,nan"),
        ("yaw -inf", "0,0,-inf"),
        ("yaw 725", "0,0,725"),
        ("yaw 5 and 725", "0,0,5\n0,0,365"),
        ("yaw -350 and 10", "1,0,-350\n1,0,10"),
        ("an empty cell", "0,,0"),
    ):

        @add("4 picks file", name)
        def _(name=name, rows=rows):
            f = tmp / f"picks_{abs(hash(name))}.csv"
            f.write_text("x_mm,y_mm,yaw_deg\n" + rows + "\n")
            folder = tmp / f"never_{abs(hash(name))}"
            res = run("evaluate", "block", "--picks", f, "--out", folder, *FAST)
            return verdict(res, refused_with="picks file", folder=folder)

    # 7: design bounds no variant fits
    for bound in ("stroke_mm=5:25", "finger_width_mm=1:2"):

        @add("7 design", bound)
        def _(bound=bound):
            folder = tmp / f"design_{bound.split('=')[0]}"
            res = run(
                "design",
                "block",
                "--bound",
                bound,
                "--n",
                "4",
                "--variants",
                "4",
                "--rounds",
                "1",
                "--out",
                folder,
                *FAST,
            )
            if res.returncode == 0:
                best = json.loads((folder / "design.json").read_text())["best"]
                field, rng = bound.split("=")
                lo, hi = map(float, rng.split(":"))
                inside = lo <= best[field] <= hi
                final = json.loads((folder / "design.json").read_text())["final"]
                row = next(r for r in final if r["gripper"] == best["name"])
                return (
                    ("handled", f"best {best['name']}")
                    if inside and row["success_rate"] > 0
                    else ("wrong", f"best {best['name']} ({row['success_rate']})")
                )
            return verdict(res, refused_with="design", folder=None)

    # 9, 17: numbers and option pairs
    for argv, said in (
        (["evaluate", "block", "--traces", "-5"], "--traces = -5"),
        (["evaluate", "block", "--traces", "1.5"], "--traces = 1.5"),
        (["evaluate", "block", "--seed", str(2**32)], "--seed = 4294967296"),
        (["evaluate", "block", "--seed", "-3"], "--seed = -3"),
        (["evaluate", "block", "--chunk-size", "0"], "--chunk-size = 0"),
        (["evaluate", "block", "--min-score", "nan"], "--min-score = nan"),
        (["evaluate", "block", "--mass-g", "10", "--density-kg-m3", "1200"], "give one"),
        (["evaluate", "block", "--unit", "m"], "does not apply"),
        (["robust", "block", "--sigma-yaw-deg", "-1"], "--sigma-yaw-deg = -1"),
        (["design", "block", "--bound", "stroke_mm=60:90", "--rounds", "0"], "--rounds = 0"),
        (["calibrate", "x.csv", "block", "--steps", "2.5"], "--steps = 2.5"),
        (["report", "nowhere", "--anim-every", "0"], "--anim-every = 0"),
        (["gui", "--port", "70000"], "--port = 70000"),
    ):

        @add("9/17 numbers", " ".join(argv[2:]) or argv[0])
        def _(argv=argv, said=said):
            folder = tmp / "never_numbers"
            needs_out = argv[0] not in ("report", "gui")
            res = run(*argv, *(["--out", folder] if needs_out else []), timeout=120)
            return verdict(res, refused_with=said, folder=folder if needs_out else None)

    # 16: sweep sizes
    for spec in (
        "contact.pad_friction=0.1:1:5000",
        "contact.pad_friction=0.1:1:1001",
        "grasp.hold_s=0.1:1:101 --param contact.pad_friction=0.1:1:101",
        "contact.pad_friction=0.1,inf",
    ):

        @add("16 sweep size", spec)
        def _(spec=spec):
            folder = tmp / "never_sweep"
            argv = ["sweep", "block"] + sum((["--param", p] for p in spec.split(" --param ")), [])
            res = run(*argv, "--n", "2", "--out", folder, *FAST)
            said = "variants" if " --param " in spec else "--param"
            return verdict(
                res,
                refused_with=said,
                folder=folder,
            )

    # 17: reports on damaged tables
    def damaged(drop=None, rows=None):
        import pyarrow.parquet as pq

        src = tmp / "report_src"
        if not (src / "results.parquet").is_file():
            run("evaluate", "block", "--n", "4", "--out", src, "--traces", "0", *FAST)
        folder = tmp / f"report_{drop}_{rows}"
        shutil.rmtree(folder, ignore_errors=True)
        shutil.copytree(src, folder)
        t = pq.read_table(folder / "results.parquet")
        if drop:
            t = t.drop([drop])
        if rows is not None:
            t = t.slice(0, rows)
        pq.write_table(t, folder / "results.parquet")
        return folder

    for drop, rows, said in (
        ("pick_id", None, "no pick_id column"),
        ("failure", None, "no failure column"),
        (None, 0, "no pick-points"),
    ):

        @add("17 report", f"{drop or ''} {'' if rows is None else f'{rows} rows'}".strip())
        def _(drop=drop, rows=rows, said=said):
            folder = damaged(drop, rows)
            res = run("report", folder, "--no-animations")
            return verdict(res, refused_with=said)

    # 18: mesh files and resume targets
    @add("18 late refusals", "STL 4 million triangles (sparse)")
    def _():
        f = tmp / "huge.stl"
        with f.open("wb") as fh:
            fh.write(b"\0" * 80 + (4_000_000).to_bytes(4, "little"))
            fh.truncate(84 + 50 * 4_000_000)
        t0 = time.monotonic()
        res = run("picks", f, "--unit", "mm", "--mass-g", "9", "--n", "2", "--out", tmp / "nv")
        v = verdict(res, refused_with="4000000 triangles")
        return (v[0], f"{v[1]} ({time.monotonic() - t0:.0f} s)")

    @add("18 late refusals", "ASCII STL cut short")
    def _():
        f = tmp / "cut_ascii.stl"
        f.write_text("solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n")
        res = run("picks", f, "--unit", "mm", "--mass-g", "9", "--n", "2", "--out", tmp / "nv")
        return verdict(res, refused_with="mesh")

    for cmd in ("sweep", "compare", "robust"):

        @add("18 late refusals", f"{cmd} --resume into a missing folder")
        def _(cmd=cmd):
            extra = {
                "sweep": ["--param", "contact.pad_friction=0.5,0.6"],
                "compare": ["--grippers", "robotiq-2f85,onrobot-rg2"],
                "robust": [],
            }[cmd]
            folder = tmp / f"missing_{cmd}"
            res = run(cmd, "block", *extra, "--n", "2", "--out", folder, "--resume", *FAST)
            return verdict(res, refused_with="does not exist", folder=folder)

    @add("18 late refusals", "compare: a 120 mm square that fits only at its corners")
    def _():
        import cv2
        import numpy as np

        img = np.full((1300, 1300, 3), 255, np.uint8)
        img[50:1250, 50:1250] = 0
        f = tmp / "square.png"
        cv2.imwrite(str(f), img)
        folder = tmp / "never_cmp"
        res = run(
            "compare",
            f,
            "--px-per-mm",
            "10",
            "--thickness-mm",
            "20",
            "--mass-g",
            "200",
            "--grippers",
            "robotiq-2f85,franka-hand",
            "--n",
            "4",
            "--out",
            folder,
            *FAST,
            timeout=300,
        )
        # handled: it runs, says the part barely fits, and ranks both at what they do
        return verdict(res, ok=lambda: "barely fits" in res.stderr)

    # 15: gripper names
    for name, good in (("grip 😀", True), ("a/b", False), ("..", False), ("x\x07y", False)):

        @add("15 gripper names", repr(name))
        def _(name=name, good=good):
            root = Path(__file__).resolve().parents[2]
            base = root / "mjx_pick/assets/grippers/onrobot-rg2.toml"
            f = tmp / f"g{abs(hash(name))}.toml"
            text = base.read_text().replace(
                'name = "onrobot-rg2"', "name = " + json.dumps(name, ensure_ascii=False)
            )
            f.write_text(text, "utf-8")
            folder = tmp / f"names{abs(hash(name))}"
            res = run(
                "evaluate",
                "block",
                "--gripper-file",
                f,
                "--n",
                "2",
                "--out",
                folder,
                "--traces",
                "0",
                *FAST,
            )
            if good:
                return verdict(
                    res,
                    ok=lambda: (
                        json.loads((folder / "config.json").read_text(encoding="utf-8"))["gripper"][
                            "name"
                        ]
                        == name
                    ),
                )
            return verdict(res, refused_with="is not allowed", folder=folder)

    return out


def run_and_count(probe_list, only: str | None, csv_path: Path, width: int = 28) -> None:
    """Run each (family, name, probe) whose family starts with only (all when None):
    one line per probe, its row in csv_path, then the counts per family."""
    rows, counts = [], {}
    for family, name, probe in probe_list:
        if only and not family.startswith(only):
            continue
        t0 = time.monotonic()
        try:
            kind, note = probe()
        except Exception as err:  # noqa: BLE001 - a probe's own failure is a wrong outcome
            kind, note = "wrong", f"probe failed: {type(err).__name__}: {err}"
        note = " ".join(str(note).split())
        counts.setdefault(family, {"refused": 0, "handled": 0, "wrong": 0})[kind] += 1
        rows.append(
            {
                "family": family,
                "probe": name,
                "class": kind,
                "note": note,
                "seconds": round(time.monotonic() - t0, 1),
            }
        )
        print(f"{family:{width}s} {name[:48]:48s} {kind:8s} {note[:110]}", flush=True)
    with csv_path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"\n{'family':{width}s}  refused  handled  wrong")
    for family, c in counts.items():
        print(f"{family:{width}s} {c['refused']:8d} {c['handled']:8d} {c['wrong']:6d}")
    total = {k: sum(c[k] for c in counts.values()) for k in ("refused", "handled", "wrong")}
    print(f"{'all':{width}s} {total['refused']:8d} {total['handled']:8d} {total['wrong']:6d}")


def probe_arguments(description: str, default_out: str) -> tuple[Path, str | None]:
    """A probe script's command line: its work folder (--out, emptied and made) and
    --only (the family prefix to run, or None)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--out", default=default_out, help="work folder (emptied first)")
    ap.add_argument("--only", help="only probes whose family starts with this")
    args = ap.parse_args()
    out = Path(args.out).resolve()
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    return out, args.only


def main() -> None:
    tmp, only = probe_arguments(__doc__.splitlines()[0], "runs/probes")
    run_and_count(probes(tmp), only, tmp / "probes.csv")


if __name__ == "__main__":
    main()
