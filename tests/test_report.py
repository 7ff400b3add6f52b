"""Reports: each file is checked for its content (pages, scale, frames, poses), not
only for being there."""

import json
import math
import re
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.outputs.reporting import PAPERS_MM, Run, report

FAST = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.2)
MM = 72.0 / 25.4  # PDF points per millimetre


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, door_opener):
    out = tmp_path_factory.mktemp("run")
    mp.evaluate(door_opener, n=16, seed=0, grasp=FAST, backend="mujoco", out=out, n_traces=1)
    return out


@pytest.fixture(scope="module")
def written(run_dir):
    return report(run_dir, n=2, k=4, anim_every=25, anim_size=(160, 120))


def _pdf_streams(path):
    data = path.read_bytes()
    for m in re.finditer(rb"stream\r?\n(.*?)\r?\nendstream", data, re.S):
        try:
            yield zlib.decompress(m.group(1))
        except zlib.error:
            continue


def test_template_pages_and_true_scale(written):
    for paper, (w_mm, h_mm) in PAPERS_MM.items():
        path = Path(written["templates"][paper])
        data = path.read_bytes()
        # 2 best + 2 worst pick-points, one page each
        assert len(re.findall(rb"/Type /Page\b(?!s)", data)) == 4
        box = re.search(rb"/MediaBox \[ ?0 0 ([\d.]+) ([\d.]+) ?\]", data)
        assert float(box.group(1)) == pytest.approx(w_mm * MM, abs=0.1)
        assert float(box.group(2)) == pytest.approx(h_mm * MM, abs=0.1)
        # the scale bar: the one stroke in its colour, 100 mm long on the page
        bars = []
        for text in _pdf_streams(path):
            for m in re.finditer(
                rb"0\.0039215686\s+0\.0078431373\s+0\.0117647059 RG.*?"
                rb"([\d.]+) ([\d.]+) m\s+([\d.]+) ([\d.]+) l",
                text,
                re.S,
            ):
                x0, y0, x1, y1 = map(float, m.groups())
                bars.append(math.hypot(x1 - x0, y1 - y0))
        assert bars, "no scale bar found"
        assert max(bars) == pytest.approx(100 * MM, abs=0.05)


# imageio's reader leaves its ffmpeg pipe to the garbage collector, and starts ffmpeg
# with a preexec_fn (a Python fork, which JAX warns of) unless told not to
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def test_animations_have_the_frames_asked_for(written, run_dir, monkeypatch):
    monkeypatch.setenv("IMAGEIO_FFMPEG_NO_PREVENT_SIGINT", "1")
    run = Run.load(run_dir)
    assert len(written["animations"]) == len(run.traced()) == 2
    for path in written["animations"]:
        pid = int(path.split("_")[-1].split(".")[0])
        ticks = len(run.trace(pid)["t_s"])
        with Image.open(path) as gif:
            assert gif.n_frames == math.ceil(ticks / 25)
            assert gif.size == (320, 120)  # top and side views side by side
            gif.seek(gif.n_frames // 2)
            pixels = np.asarray(gif.convert("RGB"), float)
        assert pixels.std() > 10, "a blank frame"
        # the same frames as an MP4 beside the GIF, played in real time
        import imageio.v2 as imageio

        video = Path(path).with_suffix(".mp4")
        assert str(video) in written["videos"]
        reader = imageio.get_reader(video, format="FFMPEG")
        try:
            meta = reader.get_meta_data()
            decoded = [frame for frame in reader]
        finally:
            reader.close()
        assert len(decoded) == math.ceil(ticks / 25)
        assert decoded[0].shape == (120, 320, 3) and meta["codec"] == "h264"
        assert meta["fps"] == pytest.approx(1 / (25 * 0.005), rel=1e-3)
        assert np.asarray(decoded[len(decoded) // 2], float).std() > 10, "a blank frame"


def test_force_plots_and_maps(written):
    assert len(written["forces"]) == 2
    for key in ("score_map", "success_by_yaw", "score_hist", "failures", *written["forces"]):
        path = written.get(key, key)
        with Image.open(path) as im:
            assert im.size[0] > 400 and np.asarray(im.convert("L")).std() > 5


def test_robot_export_poses_invert_the_pick_points(run_dir, written):
    data = json.loads(Path(written["robot_picks"]).read_text())
    picks = data["picks"]
    assert 1 <= len(picks) <= 4
    assert all(p["success"] for p in picks)
    # the successes whose label is clear first, those in doubt after, each by score
    doubt = [bool(p["label_in_doubt"]) for p in picks]
    assert doubt == sorted(doubt)
    for part in (False, True):
        scores = [p["score"] for p, d in zip(picks, doubt, strict=True) if d == part]
        assert scores == sorted(scores, reverse=True)
    for p in picks:
        t = np.asarray(p["gripper_pose"]["matrix"])
        o = p["object_in_gripper"]
        # the object's origin seen from the gripper must be the pick-point
        obj_in_grip = np.linalg.inv(t) @ np.array([0.0, 0.0, 0.0, 1.0])
        assert obj_in_grip[:2] == pytest.approx([o["x_mm"], o["y_mm"]], abs=1e-3)
        assert math.degrees(math.atan2(t[1, 0], t[0, 0])) == pytest.approx(
            -o["yaw_deg"] if o["yaw_deg"] <= 180 else 360 - o["yaw_deg"], abs=1e-3
        )
    # in a user frame 100 mm along x and turned 90 degrees about z
    shifted = report(
        run_dir, run_dir / "framed", n=1, k=1, frame=(100, 0, 0, 0, 0, 90), animations=False
    )
    moved = json.loads(Path(shifted["robot_picks"]).read_text())["picks"][0]["gripper_pose"]
    px, py, pz = picks[0]["gripper_pose"]["position_mm"]
    assert moved["position_mm"] == pytest.approx([100 - py, px, pz], abs=1e-3)


def test_html_embeds_everything(written):
    text = Path(written["html"]).read_text()
    assert text.count("data:image/png;base64,") == 4 + 2  # maps + force plots
    assert text.count("data:image/gif;base64,") == 2
    assert text.count("data:application/pdf;base64,") == 2
    assert 'src="/' not in text and 'href="/' not in text, "nothing points outside the file"


def test_cli_report_and_bad_input(run_dir, tmp_path, capsys):
    assert (
        main(["report", str(run_dir), "--out", str(tmp_path / "r"), "--no-animations", "--n", "1"])
        == 0
    )
    assert (tmp_path / "r" / "report.html").is_file()
    # progress of the report's parts on stderr: not a terminal here, so whole lines,
    # the last one once
    err = capsys.readouterr().err
    assert "\r" not in err and err.count("report: 100% 7/7 part") == 1, err
    assert main(["report", str(tmp_path)]) == 2
    assert "not an evaluate output folder" in capsys.readouterr().err
    assert main(["report", str(run_dir), "--frame", "1,2,x"]) == 2


def test_view_checks_its_inputs_then_the_display(run_dir, monkeypatch, capsys):
    import sys

    traced = [pid for pid, _ in Run.load(run_dir).traced()]
    assert main(["view", str(run_dir), "--pick", "99999"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, "one line"
    assert f"--pick 99999: not traced in {run_dir}; traced pick-points: " in err
    assert all(str(p) in err for p in traced)
    assert main(["view", str(run_dir), "--pick", str(traced[0]), "--speed", "0"]) == 2
    assert "--speed = 0.0 is out of range" in capsys.readouterr().err
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(run_dir), "--pick", str(traced[0])]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no display: neither DISPLAY nor WAYLAND_DISPLAY" in err


def test_view_replays_the_trace_row_by_row(run_dir, monkeypatch):
    # the window itself cannot open in CI; a stand-in for MuJoCo's passive viewer
    # records what each frame shows: every trace row, in order, then the window closes
    import contextlib

    import mujoco.viewer

    from mjx_pick.outputs.reporting import viewer

    run = Run.load(run_dir)
    pid = run.traced()[0][0]
    trace = run.trace(pid)
    shown = []

    class Handle:
        def __init__(self, model, data):
            self.model, self.data = model, data

        def is_running(self):
            return len(shown) < len(trace["t_s"])

        def lock(self):
            return contextlib.nullcontext()

        def set_texts(self, texts):
            self.text = texts[2]

        def sync(self):
            o = self.model.jnt_qposadr[self.model.joint("object").id]
            shown.append((self.text, self.data.qpos[o : o + 3].copy()))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(mujoco.viewer, "launch_passive", Handle)
    viewer.view(run_dir, pid, speed=100.0)
    assert len(shown) == len(trace["t_s"])
    k = len(shown) // 2
    assert shown[k][0].startswith(f"t = {trace['t_s'][k]:.2f} s  {trace['phase'][k]}")
    for k in (0, len(shown) // 2, len(shown) - 1):
        want = [trace[f"object_{c}_m"][k] for c in "xyz"]
        assert shown[k][1] == pytest.approx(want, abs=1e-9)


@pytest.mark.parametrize("damaged", ["config.json", "summary.json", "results.parquet"])
def test_a_damaged_run_file_is_an_error_naming_it(tmp_path, capsys, damaged):
    # a traceback before (JSONDecodeError, ArrowInvalid)
    folder = tmp_path / "run"
    folder.mkdir()
    config = {"object": {"outline_wkt": "POLYGON ((0 0, 10 0, 10 10, 0 0))"}, "gripper": {}}
    (folder / "config.json").write_text(json.dumps(config))
    (folder / "summary.json").write_text("{}")
    (folder / "results.parquet").write_bytes(b"PAR1 not really")
    if damaged != "results.parquet":
        (folder / damaged).write_text('{"cut off": ')
    with pytest.raises(mp.ConfigError, match=rf"{damaged} is damaged"):
        Run.load(folder)
    assert main(["report", str(folder), "--no-animations"]) == 2
    assert f"{damaged} is damaged" in capsys.readouterr().err


def test_a_headless_report_renders_every_animation_in_one_child(run_dir, tmp_path, monkeypatch):
    """A script with no display and no MUJOCO_GL renders in an EGL child: one for the
    whole report, not one per animation (each start imports MuJoCo and this package)."""
    import multiprocessing

    from mjx_pick.outputs.reporting import animation

    pools = []

    class InProcessPool:  # stands in for the spawned child: counts starts, runs here
        def __init__(self, n):
            pools.append(n)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def apply(self, fn, args):
            return _render_here(fn, args)

    def _render_here(fn, args):
        with monkeypatch.context() as m:
            m.setattr(animation, "_render_in_child", lambda: False)  # the child can render
            return fn(*args)

    class Context:
        Pool = InProcessPool

    monkeypatch.setattr(animation, "_render_in_child", lambda: True)
    monkeypatch.setattr(multiprocessing, "get_context", lambda method: Context())
    out = report(run_dir, tmp_path / "r", n=2, k=4, anim_every=200, anim_size=(80, 60))
    assert len(out["animations"]) == 2 and pools == [1]


def test_a_part_larger_than_the_page_skips_its_template_and_reports_the_rest(tmp_path, capsys):
    from shapely.geometry import box

    from mjx_pick.outputs.reporting.template import page_misfit, positioning_template

    # a 230 mm bar: within the 2F-85's stroke across its 20 mm, longer than A4's 180 mm
    # of room; letter's shorter side is 185.9 mm, so neither page holds it
    bar = mp.object_from_polygon(box(-115, -10, 115, 10), thickness_mm=10, mass_g=60)
    out = tmp_path / "bar"
    mp.evaluate(bar, n=2, seed=0, grasp=FAST, backend="mujoco", out=out, n_traces=1)
    from mjx_pick.core.config import write_atomic
    from mjx_pick.outputs.rundir import recording

    with recording(out):  # an earlier report's, recorded as a report records its files
        write_atomic(out / "template_a4.pdf", b"an earlier report's")
    assert main(["report", str(out), "--no-animations"]) == 0
    text = capsys.readouterr().out
    assert "templates: none" in text
    assert "template on a4 not written: the object (230 mm) does not fit a4 paper at 1:1" in text
    assert not (out / "template_a4.pdf").exists()  # not left to be taken for this one's
    assert (out / "report.html").is_file() and (out / "robot_picks.json").is_file()
    assert "does not fit letter paper" in (out / "report.html").read_text()
    # the function itself still refuses, naming the part's size and the room
    run = Run.load(out)
    pick = {"x_mm": 0.0, "y_mm": 0.0, "yaw_deg": 0.0, "opening_mm": 30.0, "label": "p"}
    assert page_misfit(run.outline, [pick], "a4") == (
        "the object (230 mm) does not fit a4 paper at 1:1 (at most 180 mm)"
    )
    assert page_misfit(run.outline, [{**pick, "yaw_deg": 90.0}], "a4") is not None
    with pytest.raises(mp.ConfigError, match="does not fit a4 paper"):
        positioning_template(run.outline, run.gripper, [pick], tmp_path / "t.pdf")


def test_robot_export_tries_the_labels_in_doubt_last():
    import pyarrow as pa

    from mjx_pick.outputs.reporting.robot import robot_picks

    def row(pid, score, margin, stable=True, converged=True):
        return {
            "pick_id": pid, "x_mm": 0.0, "y_mm": 0.0, "yaw_deg": 0.0, "opening_mm": 30.0,
            "score": score, "success": True, "label_margin": margin,
            "label_stable": stable, "label_converged": converged,
        }  # fmt: skip

    table = pa.Table.from_pylist(
        [
            row(1, 0.99, 0.05),  # the best score, decided within 0.1 of a threshold
            row(2, 0.98, 0.6, converged=False),  # half the step changes it
            row(3, 0.97, 0.6, stable=False),  # a small move changes it
            row(4, 0.90, 0.5),
            row(5, 0.80, 0.9),
        ]
    )
    picks = robot_picks(table, pick_height_mm=5.0, k=5)
    assert [p["pick_id"] for p in picks] == [4, 5, 1, 2, 3]
    assert [p["label_in_doubt"] for p in picks] == [
        [],
        [],
        ["by a hair"],
        ["half the step changes it"],
        ["a small move changes it"],
    ]
    assert [p["pick_id"] for p in robot_picks(table, pick_height_mm=5.0, k=2)] == [4, 5]
