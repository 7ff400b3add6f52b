"""Probe the classes of issues 56 and 57 (CLI) with inputs of its own, through the CLI.

The tests (tests/test_third_routes.py) pin the cases the issues name; this reruns each
class with other characters, encodings, folders, fields and studies. Each probe is
classified as second_routes.py does: refused (one ``mjx-pick: error:`` line naming the
input, no traceback, nothing written), handled (it succeeds and its check passes) or
wrong. Run from the repository root with mjx_pick installed:

    python benchmarks/probes/third_routes.py [--out runs/probes3] [--only FAMILY]

It prints one line per probe, the counts per family, and writes probes.csv.
"""

from __future__ import annotations

import json
import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # second_routes' counting
from second_routes import (  # noqa: E402
    FAST,
    ProbeList,
    probe_arguments,
    run,
    run_and_count,
    snapshot,
    verdict,
)

ROOT = Path(__file__).resolve().parents[2]
ASSETS = ROOT / "mjx_pick" / "assets"
BLOCK = ["--px-per-mm", "10", "--thickness-mm", "20", "--mass-g", "43.2"]


def toml_text(name: str) -> str:
    """name as a TOML basic string (the probes' own quoting, not the package's)."""
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def model_name(folder: Path) -> str:
    return ET.parse(folder / "scene.xml").getroot().get("model")


def probes(tmp: Path) -> ProbeList:
    out = ProbeList()
    add = out.add

    # A: user text into XML, TOML, HTML and shell lines -- other characters
    for name in (
        "it's",
        "&amp; literal",
        "]]> --> <!--",
        "zero\u200bwidth",
        "rtl \u202e mark",
        "line\u2028sep",
        "combo 'a' \"b\" <c> & 🤖",
        "x" * 100,
    ):

        @add("A escape: gripper name", repr(name)[:40])
        def _(name=name):
            f = tmp / f"g{abs(hash(name))}.toml"
            f.write_text(f'base = "onrobot-rg2"\nname = {toml_text(name)}\n', "utf-8")
            folder = tmp / f"gname{abs(hash(name))}"
            argv = ["evaluate", "block", "--gripper-file", f, "--n", "2", "--traces", "0"]
            res = run(*argv, "--out", folder, *FAST)
            return verdict(res, ok=lambda: model_name(folder) == f"mjx_pick block {name}")

    for name, good in (
        ("x" * 101, False),
        ("tab\there", False),
        (" lead", False),
        ("back\\slash", False),
    ):

        @add("A escape: gripper name", repr(name)[:40])
        def _(name=name, good=good):
            f = tmp / f"g{abs(hash(name))}.toml"
            f.write_text(f'base = "onrobot-rg2"\nname = {toml_text(name)}\n', "utf-8")
            folder = tmp / f"gname{abs(hash(name))}"
            res = run("evaluate", "block", "--gripper-file", f, "--out", folder, *FAST)
            return verdict(res, refused_with="is not allowed", folder=folder)

    for stem in ('it\'s "x" & <y>', "🤖", "a$b`c`", "ümlaut ß", "[1] (2) {3}"):
        for suffix in (".png", ".stl"):

            @add(f"A escape: file name {suffix}", stem)
            def _(stem=stem, suffix=suffix):
                f = tmp / f"{stem}{suffix}"
                if suffix == ".png":
                    shutil.copy(ASSETS / "objects" / "block.png", f)
                    size = BLOCK
                else:
                    import trimesh

                    trimesh.creation.box([30.0, 20.0, 15.0]).export(f)
                    size = ["--unit", "mm", "--mass-g", "9"]
                folder = tmp / f"fname{abs(hash(stem + suffix))}"
                argv = ["evaluate", f, *size, "--n", "2", "--traces", "0", "--out", folder]
                res = run(*argv, *FAST)
                return verdict(
                    res, ok=lambda: model_name(folder) == f"mjx_pick {stem} robotiq-2f85"
                )

    @add("A escape: other outputs", "compare + design with a quoted name")
    def _():
        f = tmp / "quoted.toml"
        name = 'rg2 "v2" <&>'
        f.write_text(f'base = "onrobot-rg2"\nname = {toml_text(name)}\n', "utf-8")
        folder = tmp / "design_quoted"
        argv = ["design", "block", "--gripper-file", f, "--bound", "finger_width_mm=15:30"]
        res = run(*argv, "--variants", "2", "--rounds", "1", "--n", "4", "--out", folder, *FAST)

        def ok():
            import tomllib

            best = tomllib.loads((folder / "best_gripper.toml").read_text("utf-8"))
            return best["name"].startswith(name)

        return verdict(res, ok=ok)

    @add("A escape: other outputs", "compare, ranking.json names")
    def _():
        f = tmp / "quoted2.toml"
        name = "grip 'é' % 🤖"
        f.write_text(f'base = "onrobot-rg2"\nname = {toml_text(name)}\n', "utf-8")
        folder = tmp / "compare_quoted"
        argv = ["compare", "block", "--grippers", f"{f},robotiq-2f85", "--n", "4"]
        res = run(*argv, "--out", folder, *FAST)

        def ok():
            ranking = json.loads((folder / "ranking.json").read_text("utf-8"))
            return name in {r["gripper"] for r in ranking}

        return verdict(res, ok=ok)

    # B: one reader of text files -- other encodings and files
    for what, flag, body, encoding in (
        ("UTF-16 contact", "--contact", "pad_friction = 0.9\n", "utf-16"),
        ("cp1252 euro in grasp", "--grasp", "# 5 € gripper\nhold_s = 0.1\n", "cp1252"),
        ("Shift-JIS solver", "--solver", "# ソルバー\ntimestep_s = 0.001\n", "shift_jis"),
        ("Latin-1 picks", "--picks", "x_mm,y_mm,yaw_deg\n0,0,0 # Stück\n", "latin-1"),
        ("binary .toml", "--contact", None, None),
    ):

        @add("B text files", what)
        def _(flag=flag, body=body, encoding=encoding, what=what):
            f = tmp / f"enc{abs(hash(what))}{'.csv' if flag == '--picks' else '.toml'}"
            f.write_bytes(b"\x00\xff\xfe\x89PNG" * 20 if body is None else body.encode(encoding))
            folder = tmp / f"never_enc{abs(hash(what))}"
            res = run("evaluate", "block", flag, f, "--out", folder, *FAST)
            return verdict(res, refused_with="is not UTF-8 text", folder=folder)

    for what, flag, body in (
        ("UTF-8 with BOM contact", "--contact", "\ufeffpad_friction = 0.9\n"),
        ("UTF-8 with BOM picks", "--picks", "\ufeffx_mm,y_mm,yaw_deg\n0,0,0\n"),
    ):

        @add("B text files", what)
        def _(flag=flag, body=body, what=what):
            f = tmp / f"bom{abs(hash(what))}{'.csv' if flag == '--picks' else '.toml'}"
            f.write_text(body, "utf-8")
            res = run("evaluate", "block", flag, f, "--n" if flag != "--picks" else "--seed",
                      "2" if flag != "--picks" else "0", *FAST)  # fmt: skip
            return verdict(res)

    @add("B text files", "Latin-1 outcomes CSV")
    def _():
        f = tmp / "oc_latin.csv"
        text = (ASSETS / "outcomes" / "block_1kg_rg2.csv").read_text()
        f.write_bytes(
            text.replace("trace\n", "trace\n", 1).encode() + "# Prüfung\n".encode("latin-1")
        )
        folder = tmp / "never_oc"
        res = run("calibrate", f, "block", "--mass-g", "1000", "--gripper", "onrobot-rg2",
                  "--out", folder, "--backend", "mujoco")  # fmt: skip
        return verdict(res, refused_with="is not UTF-8 text", folder=folder)

    # C: only recorded files removed; refused commands write nothing -- other routes
    def users(folder: Path) -> dict:
        mine = {"README.txt": "mine", "cad/part.step": "ISO", "deep/er/x.bin": "x"}
        for rel, text in mine.items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_text(text)
        return mine

    def kept(folder: Path, mine: dict) -> bool:
        return all((folder / rel).read_text() == text for rel, text in mine.items())

    for cmd, extra in (
        ("sweep", ["--param", "contact.pad_friction=0.5,0.9"]),
        ("compare", ["--grippers", "robotiq-2f85,onrobot-rg2"]),
        ("picks", []),
    ):

        @add("C folders: overwrite keeps the user's", cmd)
        def _(cmd=cmd, extra=extra):
            folder = tmp / f"ow_{cmd}"
            fast = FAST if cmd != "picks" else []
            run(cmd, "block", *extra, "--n", "4", "--out", folder, *fast)
            mine = users(folder)
            res = run(cmd, "block", *extra, "--n", "4", "--seed", "3", "--overwrite",
                      "--out", folder, *fast)  # fmt: skip
            return verdict(res, ok=lambda: kept(folder, mine))

    @add("C folders: overwrite keeps the user's", "robust into an evaluate folder")
    def _():
        folder = tmp / "ow_robust"
        run("evaluate", "block", "--n", "8", "--out", folder, "--traces", "0", *FAST)
        mine = users(folder)
        argv = ["robust", "block", "--results", folder, "--top-k", "2", "--m", "2"]
        run(*argv, "--out", folder, *FAST)
        res = run(*argv, "--m", "3", "--overwrite", "--out", folder, *FAST)
        return verdict(
            res, ok=lambda: kept(folder, mine) and (folder / "results.parquet").is_file()
        )

    for cmd, extra, said in (
        ("sweep", ["--param", "gripper.force_max_n=30,60"], "sweep variant"),
        ("compare", ["--grippers", "robotiq-2f85,nosuch"], "nosuch"),
        ("design", ["--bound", "pad_height_mm=-5:10"], "design bound"),
        ("robust", ["--m", "0"], "--m = 0"),
        ("evaluate", ["--fingertip-clearance-mm", "7"], "fingertip_clearance_mm"),
    ):

        @add("C folders: refused writes nothing", f"{cmd} {' '.join(extra)}"[:48])
        def _(cmd=cmd, extra=extra, said=said):
            folder = tmp / f"refused_{cmd}"
            folder.mkdir()
            res = run(cmd, "block", *extra, "--n", "4", "--out", folder, *FAST)
            v = verdict(res, refused_with=said)
            if v[0] == "refused" and any(folder.iterdir()):
                return "wrong", f"left {sorted(p.name for p in folder.iterdir())}"
            return v

    for cmd, extra in (
        ("sweep", ["--param", "contact.pad_friction=0.5,0.9"]),
        ("design", ["--bound", "finger_width_mm=15:30"]),
        ("calibrate", []),
    ):

        @add("C folders: foreign files, no lock", cmd)
        def _(cmd=cmd, extra=extra):
            folder = tmp / f"foreign_{cmd}"
            folder.mkdir()
            (folder / "thesis.tex").write_text("mine")
            first = [str(ASSETS / "outcomes" / "block_1kg_rg2.csv")] if cmd == "calibrate" else []
            if cmd == "calibrate":  # as the outcomes were measured: the folder is the problem
                extra = ["--mass-g", "1000", "--gripper", "onrobot-rg2"]
            argv = [cmd, *first, "block", *extra, "--n", "4", "--out", folder]
            res = run(*argv, "--backend", "mujoco")
            v = verdict(res, refused_with="did not write")
            names = sorted(p.name for p in folder.iterdir())
            return v if names == ["thesis.tex"] else ("wrong", f"left {names}")

    # D: nothing silently ignored, capped or redrawn -- other fields and studies
    for argv, said in (
        (["robust", "block", "--results", "RUN", "--n", "500"], "--n 500 with --results"),
        (["evaluate", "disc", "--fingertip-clearance-mm", "3"], "quarter of object 'disc'"),
        (["evaluate", "block", "--lift-height-mm", "4.9"], "allowed lift_height_mm >= 5"),
        (["sweep", "block", "--param", "grasp.lift_height_mm=1,50"], "variant grasp.lift_"),
        (["design", "block", "--bound", "finger_depth_mm=0:10"], "finger_depth_mm = 0.0"),
        (["design", "block", "--bound", "pad_height_mm=-1:5"], "pad_height_mm = -1.0"),
        (["evaluate", "block", "--picks", "PICKS", "--n", "1"], "--n 1 with"),
        (["evaluate", "block", "--until", "3", "--picks", "PICKS"], "cannot take"),
        (["picks", "block", "--out", "\t"], "empty"),
        (["report", "RUN", "--out", ""], "empty"),
        (["export", "RUN", "--format", "graspgen", "--out", " "], "empty"),
        (["report", "RUN", "--frame", "0,0,0,0,0,nan", "--out", "REP"], "6 finite numbers"),
    ):

        @add("D silent", " ".join(argv[2:])[:48])
        def _(argv=argv, said=said):
            run_dir = tmp / "d_run"
            if not (run_dir / "results.parquet").is_file():
                run("evaluate", "block", "--n", "4", "--traces", "0", "--out", run_dir, *FAST)
            picks = tmp / "d_picks.csv"
            picks.write_text("x_mm,y_mm,yaw_deg\n0,0,0\n0,0,90\n")
            subs = {"RUN": run_dir, "PICKS": picks, "REP": tmp / "never_rep"}
            argv = [subs.get(a, a) for a in argv]
            fast = FAST if argv[0] in ("evaluate", "sweep", "design", "robust") else []
            if "--lift-height-mm" in argv:  # the probe's own lift, not FAST's after it
                fast = FAST[:3]
            before = snapshot(run_dir)
            res = run(*argv, *fast)
            v = verdict(res, refused_with=said, folder=run_dir, before=before)
            if (tmp / "never_rep").exists():
                return "wrong", "report wrote before refusing"
            return v

    # E: an estimate before a long job -- other studies and sizes
    for argv in (
        ["evaluate", "door_opener", "--n", "3000", "--step-check"],
        ["evaluate", "block", "--n", "1000", "--min-force"],
        ["compare", "block", "--grippers", "robotiq-2f85,onrobot-rg2,franka-hand", "--n", "4000"],
        ["sweep", "block", "--param", "contact.pad_friction=0.2:1", "--random", "100"],
        ["design", "block", "--bound", "finger_width_mm=10:40", "--n", "2000"],
        ["calibrate", "CSV", "block", "--mass-g", "1000", "--gripper", "onrobot-rg2",
         "--steps", "2000"],
    ):  # fmt: skip

        @add("E estimate", " ".join(argv[:2] + argv[-2:])[:48])
        def _(argv=argv):
            argv = [str(ASSETS / "outcomes" / "block_1kg_rg2.csv") if a == "CSV" else a
                    for a in argv]  # fmt: skip
            folder = tmp / f"never_est{abs(hash(tuple(argv)))}"
            res = run(*argv, "--out", folder, "--backend", "mujoco", "--no-progress", timeout=120)
            return verdict(res, refused_with="pass --yes to start it", folder=folder)

    @add("E estimate", "a short run needs no --yes")
    def _():
        res = run("evaluate", "block", "--n", "20", "--traces", "0", *FAST)
        return verdict(res, ok=lambda: "--yes" not in res.stderr)

    # G: what a user reads -- other warnings and URDF errors
    @add("G messages", "an implausible density: one warning line")
    def _():
        f = tmp / "dense.stl"
        import trimesh

        trimesh.creation.box([30.0, 20.0, 15.0]).export(f)
        res = run("evaluate", f, "--unit", "mm", "--density-kg-m3", "30000", "--n", "2", *FAST)
        return verdict(
            res, ok=lambda: "mjx-pick: warning:" in res.stderr and ".py:" not in res.stderr
        )

    for what, old, new, said in (
        ("pad link", '["left_inner_finger_pad"]', '["nosuch_link"]', "[urdf] pad_left_links"),
        ("mount quat", "[0.0, 1.0, 0.0, 0.0]", "[1, 0, 0, 0]", "[urdf] mount_quat"),
        ("joint", '"finger_joint"', '"nosuch_joint"', "[urdf] joint"),
    ):

        @add("G messages", f"URDF {what}")
        def _(old=old, new=new, said=said, what=what):
            shipped = ASSETS / "grippers" / "robotiq-2f85-urdf.toml"
            text = shipped.read_text().replace('file = "', f'file = "{shipped.parent}/', 1)
            f = tmp / f"urdf_{what.replace(' ', '_')}.toml"
            f.write_text(text.replace(old, new, 1))
            res = run("evaluate", "block", "--gripper-file", f, "--n", "2", *FAST)
            v = verdict(res, refused_with=said)
            return ("wrong", "names gripper.mjcf") if "gripper.mjcf" in res.stderr else v

    return out


def main() -> None:
    tmp, only = probe_arguments(__doc__.splitlines()[0], "runs/probes3")
    run_and_count(probes(tmp), only, tmp / "probes.csv", width=40)


if __name__ == "__main__":
    main()
