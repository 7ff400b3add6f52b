"""Reports a person can read, made from an ``evaluate`` output folder.

``report(run_dir)`` (``mjx-pick report DIR``) writes, beside the results or into
``out``:

* ``forces_<pick>.png`` -- the paper's Figs. 8, 15, 17, 19 for each traced pick-point:
  left and right pad force, object-table force, F_d dashed, phase changes marked;
* ``score_map.png``, ``success_by_yaw.png``, ``score_hist.png``, ``failures.png`` --
  pick-points on the silhouette coloured by score; success rate over (x, y) per yaw
  bin; the score histogram; failure reasons;
* ``anim_<pick>.gif`` -- the traced pick-points replayed in MuJoCo's offscreen renderer
  (EGL or OSMesa), top and side cameras, time and phase written on every frame;
* ``template_a4.pdf`` / ``template_letter.pdf`` -- a printable 1:1 positioning template:
  one page per pick-point (n best, then n worst), the object's outline at its pose
  around a crosshair at the gripper centre, the finger footprints at the starting
  opening, a 100 mm scale bar; place the real object on the outline under the real
  gripper;
* ``robot_picks.json`` -- the top-k pick-points as gripper poses, optionally in a frame
  of the user's;
* ``report.html`` -- all of the above in one file that opens offline.

Traces come from ``traces.parquet`` (``evaluate(n_traces=...)``); every trace row holds
the whole joint state, so animations replay it and simulate nothing.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import io
import json
import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import shapely
import shapely.affinity

from mjx_pick.config import ConfigError, from_mapping, write_atomic, write_json
from mjx_pick.gripper import GripperSpec
from mjx_pick.kernels import grasp as gk
from mjx_pick.mjcf_gripper import PREFIX, characterise
from mjx_pick.plots import add_polygon, draw_candidates, new_figure, save_png

PAPERS_MM = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}
SCALE_BAR_COLOUR = "#010203"  # a colour nothing else uses: tests find the bar by it
PHASE_COLOURS = {
    "settle": "#999999",
    "close": "#1f77b4",
    "dwell": "#9467bd",
    "lift": "#2ca02c",
    "hold": "#ff7f0e",
    "done": "#444444",
}


@dataclasses.dataclass
class Run:
    """An evaluate output folder, read back."""

    path: Path
    table: pa.Table
    traces: pa.Table | None
    config: dict
    summary: dict
    outline: shapely.Polygon  # object silhouette, mm, object frame
    gripper: GripperSpec

    @classmethod
    def load(cls, run_dir: str | os.PathLike) -> Run:
        path = Path(run_dir)
        need = ("results.parquet", "config.json", "summary.json")
        missing = [n for n in need if not (path / n).is_file()]
        if missing:
            raise ConfigError(
                f"{path} is not an evaluate output folder: missing {', '.join(missing)}"
            )
        config = json.loads((path / "config.json").read_text())
        wkt = config.get("object", {}).get("outline_wkt")
        if not wkt:
            raise ConfigError(f"{path}/config.json has no object outline (made by an old version)")
        traces = (
            pq.read_table(path / "traces.parquet") if (path / "traces.parquet").is_file() else None
        )
        return cls(
            path=path,
            table=pq.read_table(path / "results.parquet"),
            traces=traces,
            config=config,
            summary=json.loads((path / "summary.json").read_text()),
            outline=shapely.from_wkt(wkt),
            gripper=from_mapping(GripperSpec, config["gripper"]),
        )

    def trace(self, pick_id: int) -> dict[str, np.ndarray]:
        """One pick-point's trace: TRACE_FIELDS columns (T,), phase as names."""
        if self.traces is None:
            raise ConfigError(f"{self.path} has no traces.parquet (evaluate with n_traces > 0)")
        ids = np.asarray(self.traces["pick_id"])
        rows = self.traces.filter(pa.array(ids == pick_id))
        if rows.num_rows == 0:
            raise ConfigError(f"pick-point {pick_id} was not traced in {self.path}")
        return {name: np.asarray(rows[name]) for name in rows.column_names}

    def traced(self) -> list[tuple[int, str]]:
        """(pick_id, 'best' | 'worst') of every traced pick-point, best first."""
        if self.traces is None:
            return []
        ids = np.asarray(self.traces["pick_id"])
        ranks = np.asarray(self.traces["rank"].to_pylist(), dtype=object)
        seen = {}
        for i, r in zip(ids, ranks, strict=True):
            seen.setdefault(int(i), r)
        return sorted(seen.items(), key=lambda kv: kv[1] != "best")

    def row(self, pick_id: int) -> dict:
        ids = np.asarray(self.table["pick_id"])
        k = int(np.flatnonzero(ids == pick_id)[0])
        return {name: self.table[name][k].as_py() for name in self.table.column_names}


def phase_events(t: np.ndarray, phase: np.ndarray) -> list[tuple[float, str]]:
    """(time, phase entered) at every change of phase along a trace."""
    change = np.flatnonzero(phase[1:] != phase[:-1]) + 1
    return [(float(t[i]), str(phase[i])) for i in change]


def force_plot(trace: dict, grip_force_n: float, path, title: str = "") -> None:
    """Pad forces and object-table force against time, F_d dashed, phases marked."""
    t = trace["t_s"]
    fig, ax = new_figure(figsize=(8, 4))
    ax.plot(t, trace["force_left_n"], label="left finger", color="#1f77b4")
    ax.plot(t, trace["force_right_n"], label="right finger", color="#d62728", ls="-.")
    ax.plot(t, trace["force_table_n"], label="object-table", color="#7f7f7f")
    ax.axhline(grip_force_n, color="k", ls="--", lw=1, label=f"F_d = {grip_force_n:g} N")
    top = max(grip_force_n, float(np.nanmax(trace["force_left_n"]))) * 1.15
    for when, name in phase_events(t, trace["phase"]):
        ax.axvline(when, color=PHASE_COLOURS.get(name, "k"), lw=0.8, ls=":")
        ax.text(
            when,
            top,
            f" {name}",
            rotation=90,
            va="top",
            fontsize=8,
            color=PHASE_COLOURS.get(name, "k"),
        )
    ax.set_ylim(min(0.0, float(np.nanmin(trace["force_table_n"]))) - 1, top * 1.05)
    ax.set_xlabel("time, s")
    ax.set_ylabel("force, N")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="center right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def maps(run: Run, out_dir: Path, yaw_bins: int = 4) -> dict[str, Path]:
    """score_map, success_by_yaw, score_hist and failures PNGs."""
    t = run.table
    x, y, yaw = (np.asarray(t[c], float) for c in ("x_mm", "y_mm", "yaw_deg"))
    score = np.nan_to_num(np.asarray(t["score"], float), nan=0.0)
    success = np.asarray(t["success"], bool)
    out = {}
    draw_candidates(
        run.outline,
        x,
        y,
        yaw,
        out_dir / "score_map.png",
        values=score,
        title=f"{len(x)} pick-points by score (gripper centre, object frame)",
    )
    out["score_map"] = out_dir / "score_map.png"

    # the gripper is symmetric: yaw and yaw + 180 are the same grasp
    folded = np.mod(yaw, 180.0)
    edges = np.linspace(0.0, 180.0, yaw_bins + 1)
    fig, axes = new_figure(1, yaw_bins, figsize=(3.6 * yaw_bins, 3.6), squeeze=False)
    lim = max(np.abs(x).max(), np.abs(y).max(), 1.0)
    bins = np.linspace(-lim, lim, 13)
    for k, ax in enumerate(axes[0]):
        m = (folded >= edges[k]) & (folded < edges[k + 1])
        n, _, _ = np.histogram2d(x[m], y[m], bins=[bins, bins])
        s, _, _ = np.histogram2d(x[m], y[m], bins=[bins, bins], weights=success[m])
        rate = np.where(n > 0, s / np.maximum(n, 1), np.nan)
        im = ax.imshow(
            rate.T, origin="lower", extent=(-lim, lim, -lim, lim), vmin=0, vmax=1, cmap="RdYlGn"
        )
        ax.set_title(f"yaw {edges[k]:.0f}-{edges[k + 1]:.0f} deg ({int(m.sum())})", fontsize=9)
        ax.set_xlabel("x offset, mm")
        if k == 0:
            ax.set_ylabel("y offset, mm")
    fig.colorbar(im, ax=axes[0].tolist(), label="success rate", shrink=0.8)
    save_png(fig, out_dir / "success_by_yaw.png")
    out["success_by_yaw"] = out_dir / "success_by_yaw.png"

    fig, ax = new_figure(figsize=(6, 3.5))
    raw = np.asarray(t["score"], float)
    scored = np.isfinite(raw)  # diverged pick-points have no score
    ax.hist(
        [raw[scored & success], raw[scored & ~success]],
        bins=np.linspace(0, 1, 26),
        stacked=True,
        color=["#2ca02c", "#d62728"],
        label=["success", "failure"],
    )
    ax.set_xlabel("score, eq. (2)")
    ax.set_ylabel("pick-points")
    ax.legend()
    fig.tight_layout()
    save_png(fig, out_dir / "score_hist.png")
    out["score_hist"] = out_dir / "score_hist.png"

    names = list(gk.FAILURES)
    failures = np.asarray(t["failure"].to_pylist(), dtype=object)
    counts = [int(np.sum(failures == name)) for name in names]
    fig, ax = new_figure(figsize=(6, 3.5))
    ax.barh(
        names[::-1],
        counts[::-1],
        color=["#2ca02c" if n == "none" else "#d62728" for n in names[::-1]],
    )
    for i, c in enumerate(counts[::-1]):
        ax.text(c, i, f" {c}", va="center", fontsize=8)
    ax.set_xlabel("pick-points")
    ax.set_title("outcome ('none': success)")
    fig.tight_layout()
    save_png(fig, out_dir / "failures.png")
    out["failures"] = out_dir / "failures.png"
    return out


def animate(
    scene_xml: str | os.PathLike,
    trace: dict,
    path: str | os.PathLike,
    every: int = 8,
    size: tuple[int, int] = (320, 240),
    gripper: GripperSpec | None = None,
) -> int:
    """Replay a trace in MuJoCo's offscreen renderer as a GIF; returns the frame count.

    An MJCF gripper (gripper.mjcf) is posed from the traced pad travel through its
    measured close (``mjx_pick.mjcf_gripper``).

    Each frame is the top camera beside the side camera (each ``size`` = (width,
    height) pixels), with the time and phase written on it; one frame every ``every``
    control ticks, played in real time.
    """
    import mujoco
    from PIL import Image, ImageDraw

    model = mujoco.MjModel.from_xml_path(str(scene_xml))
    data = mujoco.MjData(model)
    w, h = size
    try:
        renderer = mujoco.Renderer(model, h, w)
    except Exception as err:  # noqa: BLE001 - any GL failure gets the same advice
        raise RuntimeError(
            "MuJoCo's offscreen renderer could not start: set MUJOCO_GL=egl (or osmesa) "
            "before Python starts and install libegl1 (or libosmesa6)"
        ) from err
    linkage = None if gripper is None or gripper.mjcf is None else characterise(gripper.mjcf)
    fingers = () if linkage else ("finger_left", "finger_right")
    adr = {j: int(model.jnt_qposadr[model.joint(j).id]) for j in ("object", "lift", *fingers)}
    if linkage:
        links = [int(model.jnt_qposadr[model.joint(PREFIX + j).id]) for j in linkage.joint_names]
    cams = []
    for elevation, distance, lookat_z in ((-90.0, 0.25, 0.02), (-8.0, 0.38, 0.07)):
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = (0.0, 0.0, lookat_z)
        cam.distance, cam.azimuth, cam.elevation = distance, 90.0, elevation
        option = mujoco.MjvOption()
        if elevation < -45:  # from the top, the gripper's body would hide the object
            option.geomgroup[2] = 0
        cams.append((cam, option))
    frames = []
    dt = float(trace["t_s"][1] - trace["t_s"][0]) if len(trace["t_s"]) > 1 else 0.005
    try:
        for k in range(0, len(trace["t_s"]), every):
            o = adr["object"]
            data.qpos[o : o + 3] = [trace[f"object_{c}_m"][k] for c in "xyz"]
            data.qpos[o + 3 : o + 7] = [trace[f"object_q{c}"][k] for c in "wxyz"]
            data.qpos[adr["lift"]] = trace["lift_m"][k]
            if linkage:
                travel = 0.5 * (trace["finger_left_m"][k] + trace["finger_right_m"][k])
                data.qpos[links] = linkage.joint_positions(travel)[0]
            else:
                data.qpos[adr["finger_left"]] = trace["finger_left_m"][k]
                data.qpos[adr["finger_right"]] = trace["finger_right_m"][k]
            mujoco.mj_forward(model, data)
            views = []
            for cam, option in cams:
                renderer.update_scene(data, camera=cam, scene_option=option)
                views.append(renderer.render())
            img = Image.fromarray(np.concatenate(views, axis=1))
            draw = ImageDraw.Draw(img)
            draw.text(
                (6, 4), f"t = {trace['t_s'][k]:.2f} s  {trace['phase'][k]}", fill=(255, 255, 255)
            )
            draw.text((w + 6, 4), "side", fill=(255, 255, 255))
            frames.append(img.convert("P", palette=Image.Palette.ADAPTIVE))
    finally:
        renderer.close()
    buf = io.BytesIO()
    frames[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=frames[1:],
        duration=max(20, int(round(1000 * dt * every))),
        loop=0,
    )
    write_atomic(path, buf.getvalue())
    return len(frames)


def _pose(x_mm: float, y_mm: float, yaw_deg: float, outline: shapely.Polygon):
    return shapely.affinity.translate(
        shapely.affinity.rotate(outline, yaw_deg, origin=(0, 0)), x_mm, y_mm
    )


def positioning_template(
    outline: shapely.Polygon,
    gripper: GripperSpec,
    picks: list[dict],
    path: str | os.PathLike,
    paper: str = "a4",
    title: str = "",
) -> int:
    """Printable 1:1 template, one page per pick-point; returns the page count.

    picks: dicts with x_mm, y_mm, yaw_deg, opening_mm and a label. Page coordinates
    are millimetres (the axes fill the page), so the drawing is at true scale when
    printed at 100 % ("actual size").
    """
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    if paper not in PAPERS_MM:
        raise ConfigError(f"paper = {paper!r} is not allowed: choose {', '.join(PAPERS_MM)}")
    pw, ph = PAPERS_MM[paper]
    cx, cy = pw / 2, ph / 2 + 15
    buf = io.BytesIO()
    with PdfPages(buf) as pdf:
        for number, pick in enumerate(picks, start=1):
            fig = Figure(figsize=(pw / 25.4, ph / 25.4))
            ax = fig.add_axes((0, 0, 1, 1))
            ax.set_xlim(0, pw)
            ax.set_ylim(0, ph)
            ax.set_axis_off()
            posed = shapely.affinity.translate(
                _pose(pick["x_mm"], pick["y_mm"], pick["yaw_deg"], outline), cx, cy
            )
            extent = max(posed.bounds[2] - posed.bounds[0], posed.bounds[3] - posed.bounds[1])
            if extent > min(pw, ph) - 30:
                raise ConfigError(
                    f"the object ({extent:.0f} mm) does not fit a {paper} page at 1:1"
                )
            add_polygon(ax, posed, fc="#cfe0f5", ec="k", lw=1.2)
            half = 0.5 * pick["opening_mm"]
            d, w = gripper.finger_depth_mm, gripper.finger_width_mm
            for x0 in (cx - half - d, cx + half):
                ax.add_patch(
                    Rectangle((x0, cy - w / 2), d, w, fc="#333333", alpha=0.55, ec="k", lw=0.8)
                )
            ax.plot([cx - 12, cx + 12], [cy, cy], color="r", lw=0.6)
            ax.plot([cx, cx], [cy - 12, cy + 12], color="r", lw=0.6)
            ax.add_patch(Circle((cx, cy), 2.0, fill=False, ec="r", lw=0.6))
            ax.annotate(
                "",
                xy=(cx + half + d + 10, cy + w / 2 + 8),
                xytext=(cx + half + d - 10, cy + w / 2 + 8),
                arrowprops={"arrowstyle": "<->", "lw": 0.6},
            )
            ax.text(
                cx + half + d, cy + w / 2 + 10, "closing axis (gripper x)", fontsize=6, ha="center"
            )
            ax.text(pw / 2, ph - 15, f"{title}", ha="center", fontsize=11)
            ax.text(pw / 2, ph - 23, f"{number}. {pick['label']}", ha="center", fontsize=10)
            ax.text(
                pw / 2,
                ph - 30,
                f"object at x = {pick['x_mm']:.1f} mm, y = {pick['y_mm']:.1f} mm, yaw = "
                f"{pick['yaw_deg']:.1f} deg from the gripper centre (crosshair); "
                f"opening {pick['opening_mm']:.1f} mm",
                ha="center",
                fontsize=7,
            )
            ax.plot([20, 120], [20, 20], color=SCALE_BAR_COLOUR, lw=2, solid_capstyle="butt")
            for xt in (20, 70, 120):
                ax.plot([xt, xt], [18, 22], color=SCALE_BAR_COLOUR, lw=0.8)
            ax.text(
                70,
                24,
                "100 mm: check it measures 100 mm (print at actual size)",
                ha="center",
                fontsize=7,
            )
            pdf.savefig(fig)
    write_atomic(path, buf.getvalue())
    return len(picks)


def _rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def frame_matrix(frame) -> np.ndarray:
    """4x4 transform (mm) from (x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg)."""
    from scipy.spatial.transform import Rotation

    values = [float(v) for v in frame]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ConfigError(
            f"frame = {frame!r} must be 6 finite numbers: x_mm, y_mm, z_mm, roll_deg, "
            "pitch_deg, yaw_deg (the object frame's pose in your frame)"
        )
    t = np.eye(4)
    t[:3, :3] = Rotation.from_euler("xyz", values[3:], degrees=True).as_matrix()
    t[:3, 3] = values[:3]
    return t


def robot_picks(
    table: pa.Table,
    pick_height_mm: float,
    k: int = 10,
    frame=None,
    robust: pa.Table | None = None,
) -> list[dict]:
    """The top-k pick-points (by robust probability when given, else by score among
    successes) as gripper poses.

    A pick-point is the object's pose in the gripper frame; the robot needs the
    gripper's pose in the object frame (origin at the centre of mass, on the table; z
    up) -- its inverse, at the pick height -- or, with frame (the object frame's pose in
    the user's frame, see frame_matrix), in the user's frame. The gripper frame is this
    project's: x the closing axis, z up (the gripper approaches along -z).
    """
    from scipy.spatial.transform import Rotation

    rows = table.to_pylist()
    by_id = {r["pick_id"]: r for r in rows}
    if robust is not None:
        order = [r["pick_id"] for r in robust.to_pylist() if r["pick_id"] in by_id]
        prob = {r["pick_id"]: r for r in robust.to_pylist()}
    else:
        from mjx_pick.metrics import best_successes

        best = best_successes(np.asarray(table["success"]), np.asarray(table["score"], float), k)
        order = [rows[i]["pick_id"] for i in best]
        prob = {}
    user = frame_matrix(frame) if frame is not None else None
    out = []
    for pid in order[:k]:
        r = by_id[pid]
        rot = _rot_z(-r["yaw_deg"])  # gripper axes in the object frame
        pos = -rot @ np.array([r["x_mm"], r["y_mm"], 0.0]) + np.array([0, 0, pick_height_mm])
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = rot, pos
        if user is not None:
            t = user @ t
        q = Rotation.from_matrix(t[:3, :3]).as_quat()  # x, y, z, w
        entry = {
            "pick_id": int(pid),
            "object_in_gripper": {"x_mm": r["x_mm"], "y_mm": r["y_mm"], "yaw_deg": r["yaw_deg"]},
            "gripper_pose": {
                "frame": "user" if user is not None else "object",
                "position_mm": [round(float(v), 4) for v in t[:3, 3]],
                "quaternion_wxyz": [round(float(v), 6) for v in (q[3], q[0], q[1], q[2])],
                "matrix": [[round(float(v), 6) for v in row] for row in t],
            },
            "opening_mm": r["opening_mm"],
            "score": r["score"],
            "success": r["success"],
            "success_probability": prob[pid]["robust_p"] if pid in prob else None,
            "success_probability_ci": [prob[pid]["robust_ci_low"], prob[pid]["robust_ci_high"]]
            if pid in prob
            else None,
        }
        out.append(entry)
    return out


def _embed(path: Path, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode()


def report(
    run_dir: str | os.PathLike,
    out: str | os.PathLike | None = None,
    *,
    n: int = 3,
    k: int = 10,
    frame=None,
    animations: bool = True,
    anim_every: int = 8,
    anim_size: tuple[int, int] = (320, 240),
) -> dict[str, object]:
    """Every part of the report for an evaluate output; returns what was written.

    n: best and worst pick-points on the template (and animated/plotted when traced);
    k: pick-points in the robot export; frame: see robot_picks.
    """
    run = Run.load(run_dir)
    out_dir = Path(out) if out is not None else run.path
    out_dir.mkdir(parents=True, exist_ok=True)
    written: dict[str, object] = {}
    f_d = float(run.config["grasp"]["grip_force_n"])
    name = run.config["object"]["name"]

    forces, anims = [], []
    for pid, rank in run.traced():
        trace = run.trace(pid)
        row = run.row(pid)
        label = (
            f"pick {pid} ({rank}): score {row['score']:.3f}, {row['failure']}"
            if row["score"] is not None
            else f"pick {pid} ({rank}): {row['failure']}"
        )
        p = out_dir / f"forces_{pid}.png"
        force_plot(trace, f_d, p, title=label)
        forces.append((p, label))
        if animations:
            g = out_dir / f"anim_{pid}.gif"
            frames = animate(run.path / "scene.xml", trace, g, anim_every, anim_size, run.gripper)
            anims.append((g, f"{label} ({frames} frames)"))
    written["forces"] = [str(p) for p, _ in forces]
    written["animations"] = [str(p) for p, _ in anims]
    written.update({key: str(p) for key, p in maps(run, out_dir).items()})

    score = np.asarray(run.table["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, score))
    best, worst = order[::-1][:n], order[:n]
    chosen = []
    for label, idx in (("best", best), ("worst", worst)):
        for j, i in enumerate(idx, start=1):
            r = {
                c: run.table[c][int(i)].as_py()
                for c in ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "score", "failure")
            }
            s = "NaN" if r["score"] is None else f"{r['score']:.3f}"
            r["label"] = f"{label} {j}: pick {r['pick_id']}, score {s}, {r['failure']}"
            chosen.append(r)
    templates = {}
    for paper in PAPERS_MM:
        p = out_dir / f"template_{paper}.pdf"
        positioning_template(
            run.outline,
            run.gripper,
            chosen,
            p,
            paper,
            title=f"{name} / {run.gripper.name}: positioning template",
        )
        templates[paper] = p
    written["templates"] = {k_: str(v) for k_, v in templates.items()}

    robust_path = run.path / "robustness.parquet"
    robust = pq.read_table(robust_path) if robust_path.is_file() else None
    tip_mm = float(run.config["scene"]["fingertip_height_mm"])
    picks = robot_picks(run.table, tip_mm, k, frame, robust)
    write_json(
        out_dir / "robot_picks.json",
        {
            "object": name,
            "gripper": run.gripper.name,
            "units": "mm, quaternion w x y z",
            "frame": "user frame given as " + json.dumps(list(frame))
            if frame is not None
            else "object frame: origin at the centre of mass on the table, z up",
            "picks": picks,
        },
    )
    written["robot_picks"] = str(out_dir / "robot_picks.json")

    written["html"] = str(_html(run, out_dir, forces, anims, templates, picks))
    return written


def _html(run: Run, out_dir: Path, forces, anims, templates, picks) -> Path:
    s = run.summary
    rows = "".join(
        f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"
        for k, v in (
            ("object / gripper", f"{s.get('object')} / {s.get('gripper')}"),
            ("backend / device", f"{s.get('backend')} / {s.get('device')}"),
            ("pick-points", s.get("n")),
            ("success rate", f"{s.get('success_rate', float('nan')):.3f}"),
            ("diverged", s.get("diverged")),
            ("score mean", f"{s.get('score_mean', float('nan')):.3f}"),
            ("F_Gmin, eq. (1)", f"{s.get('f_gmin_n', float('nan')):.3f} N"),
            ("failures", ", ".join(f"{k_} {v}" for k_, v in s.get("failures", {}).items() if v)),
        )
    )
    img = lambda p, cap: (  # noqa: E731
        f'<figure><img src="{_embed(p, "image/png" if p.suffix == ".png" else "image/gif")}">'
        f"<figcaption>{html.escape(cap)}</figcaption></figure>"
    )
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>mjx_pick report: {html.escape(str(s.get('object')))}</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "img{max-width:100%}figure{display:inline-block;margin:6px}"
        "td,th{text-align:left;padding:2px 10px}</style></head><body>",
        f"<h1>Pick-point report: {html.escape(str(s.get('object')))}</h1>",
        f"<table>{rows}</table>",
        "<h2>Pick-point maps</h2>",
        img(out_dir / "score_map.png", "pick-points by score"),
        img(out_dir / "success_by_yaw.png", "success rate over (x, y) per yaw bin"),
        img(out_dir / "score_hist.png", "score histogram"),
        img(out_dir / "failures.png", "failure reasons"),
        "<h2>Forces</h2>",
        *(img(p, cap) for p, cap in forces),
        "<h2>Animations</h2>",
        *(img(p, cap) for p, cap in anims),
        "<h2>Positioning templates (print at actual size)</h2><ul>",
        *(
            f'<li><a download="{p.name}" href="{_embed(p, "application/pdf")}">{p.name}</a></li>'
            for p in templates.values()
        ),
        "</ul><h2>Robot export</h2>",
        f"<pre>{html.escape(json.dumps(picks, indent=1))}</pre>",
        "</body></html>",
    ]
    path = out_dir / "report.html"
    write_atomic(path, "\n".join(parts))
    return path
