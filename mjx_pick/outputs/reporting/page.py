"""``report``: every part of a report written together, and the one-file HTML page."""

from __future__ import annotations

import base64
import contextlib
import json
import os
from pathlib import Path

import numpy as np

from mjx_pick.core import numbers
from mjx_pick.core.config import ConfigError, write_atomic, write_json
from mjx_pick.core.escape import html_text
from mjx_pick.core.metrics import label_check_rows, rate_text
from mjx_pick.outputs.progress import ProgressBar
from mjx_pick.outputs.reporting.animation import animate, render_pool
from mjx_pick.outputs.reporting.figures import force_plot, maps
from mjx_pick.outputs.reporting.robot import frame_matrix, robot_picks
from mjx_pick.outputs.reporting.run import Run, read_parquet
from mjx_pick.outputs.reporting.template import PAPERS_MM, page_misfit, positioning_template
from mjx_pick.outputs.rundir import check_out, record_file, recording, remove_recorded

__all__ = ["report"]


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
    progress: bool = False,
) -> dict[str, object]:
    """Every part of the report for an evaluate output; returns what was written.

    n: best and worst pick-points on the template (and animated/plotted when traced);
    k: pick-points in the robot export; frame: see robot_picks. animations: each traced
    pick-point replayed as anim_<pick>.gif and anim_<pick>.mp4 (``animate``), one frame
    every anim_every control ticks, each view anim_size = (width, height) pixels.
    progress: a progress bar of the report's parts on stderr.
    """
    # every input checked before the first file is written (a bad frame once refused
    # only after the figures and the PDF)
    check_out(out)
    if frame is not None:
        frame_matrix(frame)
    n, k = numbers.check("report_n", n, "--n"), numbers.check("report_k", k, "--k")
    run = Run.load(run_dir)
    if anim_every < 1:
        raise ConfigError(f"--anim-every {anim_every}: allowed >= 1 (control ticks per frame)")
    out_dir = Path(out) if out is not None else run.path
    out_dir.mkdir(parents=True, exist_ok=True)
    written: dict[str, object] = {}
    f_d = float(run.config["grasp"]["grip_force_n"])
    name = run.config["object"]["name"]
    traced = run.traced()
    # parts: per traced pick-point a force plot (and an animation), the maps, each
    # template, the robot export, the page
    parts = len(traced) * (2 if animations else 1) + 1 + len(PAPERS_MM) + 2
    pool = render_pool() if animations and traced else contextlib.nullcontext()
    bar = ProgressBar("report", "part", enabled=progress, total=parts)
    # the run's folder records the report's files: an --overwrite of the run removes them
    with recording(out_dir), bar, pool as child:
        anim = (anim_every, anim_size, child) if animations else None
        forces, anims = _traced_parts(run, out_dir, traced, f_d, anim, bar)
        written["forces"] = [str(p) for p, _ in forces]
        written["animations"] = [str(p) for p, _ in anims]
        written["videos"] = [str(p.with_suffix(".mp4")) for p, _ in anims]
        written.update({key: str(p) for key, p in maps(run, out_dir).items()})
        bar.advance()

        chosen = _template_picks(run, n)
        templates, skipped = _templates(run, out_dir, chosen, name, bar)
        written["templates"] = {k_: str(v) for k_, v in templates.items()}
        written["templates_skipped"] = skipped

        picks = _robot_export(run, out_dir, k, frame, name)
        written["robot_picks"] = str(out_dir / "robot_picks.json")
        bar.advance()

        written["html"] = str(_html(run, out_dir, forces, anims, templates, skipped, picks))
        bar.advance()
        return written


def _traced_parts(run: Run, out_dir: Path, traced, f_d: float, anim, bar) -> tuple[list, list]:
    """Per traced pick-point (traced: (pick_id, rank)) its force plot and, with anim =
    (anim_every, anim_size, render pool), its animation. Returns ([(path, label)] of
    the plots, of the animations)."""
    forces, anims = [], []
    for pid, rank in traced:
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
        bar.advance()
        if anim is not None:
            anim_every, anim_size, child = anim
            g = out_dir / f"anim_{pid}.gif"
            for written in (g, g.with_suffix(".mp4")):  # written in a render process
                record_file(written)
            frames = animate(
                run.path / "scene.xml", trace, g, anim_every, anim_size, run.gripper,
                pool=child,
            )  # fmt: skip
            anims.append((g, f"{label} ({frames} frames; video: {g.with_suffix('.mp4').name})"))
            bar.advance()
    return forces, anims


def _template_picks(run: Run, n: int) -> list[dict]:
    """The n best and n worst pick-points by score, labelled, for the templates."""
    score = np.asarray(run.table["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, score))
    best, worst = order[::-1][:n], order[:n]
    chosen = []
    for label, idx in (("best", best), ("worst", worst)):
        for j, i in enumerate(idx, start=1):
            r = {
                c: run.table[c][int(i)].as_py()
                for c in (
                    "pick_id",
                    "x_mm",
                    "y_mm",
                    "yaw_deg",
                    "opening_mm",
                    "score",
                    "failure",
                )
            }
            s = "NaN" if r["score"] is None else f"{r['score']:.3f}"
            r["label"] = f"{label} {j}: pick {r['pick_id']}, score {s}, {r['failure']}"
            chosen.append(r)
    return chosen


def _templates(run: Run, out_dir: Path, chosen: list, name: str, bar) -> tuple[dict, dict]:
    """The 1:1 positioning template of chosen on each paper size the part fits:
    ({paper: path}, {paper: why it was not written})."""
    templates, skipped = {}, {}
    tilted = "grasp_pose" in run.table.column_names
    for paper in PAPERS_MM:
        misfit = (
            "grasps given as poses are no top-down placements: a 1:1 template shows pick-points"
            if tilted
            else page_misfit(run.outline, chosen, paper)
        )
        if misfit:
            # a part larger than the page: the rest of the report is still worth having
            skipped[paper] = misfit
            remove_recorded(out_dir, f"template_{paper}.pdf")  # an earlier report's
            bar.advance()
            continue
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
        bar.advance()
    return templates, skipped


def _robot_export(run: Run, out_dir: Path, k: int, frame, name: str) -> list[dict]:
    """robot_picks.json: the k best pick-points (robust ones first when the folder holds
    robustness.parquet) in the object's frame or frame; returns them."""
    robust_path = run.path / "robustness.parquet"
    robust = read_parquet(robust_path) if robust_path.is_file() else None
    tip_mm = float(run.config["scene"]["fingertip_height_mm"])
    picks = robot_picks(run.table, tip_mm, k, frame, robust, run.gripper.pad_height_mm)
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
    return picks


def _html(run: Run, out_dir: Path, forces, anims, templates, skipped, picks) -> Path:
    """report.html; templates: {paper: path}, skipped: {paper: why it was not written}."""
    s = run.summary
    rows = "".join(
        f"<tr><th>{html_text(str(k))}</th><td>{html_text(str(v))}</td></tr>"
        for k, v in (
            ("object / gripper", f"{s.get('object')} / {s.get('gripper')}"),
            ("backend / device", f"{s.get('backend')} / {s.get('device')}"),
            ("pick-points", s.get("n")),
            ("success rate", rate_text(s.get("successes", 0), s.get("n", 0))),
            ("diverged", s.get("diverged")),
            ("score mean", f"{s.get('score_mean', float('nan')):.3f}"),
            ("F_Gmin, eq. (1)", f"{s.get('f_gmin_n', float('nan')):.3f} N"),
            ("outcomes", ", ".join(f"{k_} {v}" for k_, v in s.get("failures", {}).items() if v)),
            *label_check_rows(s),
        )
    )
    img = lambda p, cap: (  # noqa: E731
        f'<figure><img src="{_embed(p, "image/png" if p.suffix == ".png" else "image/gif")}">'
        f"<figcaption>{html_text(cap)}</figcaption></figure>"
    )
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>mjx_pick report: {html_text(str(s.get('object')))}</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "img{max-width:100%}figure{display:inline-block;margin:6px}"
        "td,th{text-align:left;padding:2px 10px}</style></head><body>",
        f"<h1>Pick-point report: {html_text(str(s.get('object')))}</h1>",
        f"<table>{rows}</table>",
        "<h2>Pick-point maps</h2>",
        img(out_dir / "score_map.png", "pick-points by score"),
        img(out_dir / "success_by_yaw.png", "success rate over (x, y) per yaw bin"),
        img(out_dir / "score_hist.png", "score histogram"),
        img(out_dir / "failures.png", "outcomes: success, or why it failed"),
        "<h2>Forces</h2>",
        *(img(p, cap) for p, cap in forces),
        "<h2>Animations</h2>",
        *(img(p, cap) for p, cap in anims),
        "<h2>Positioning templates (print at actual size)</h2><ul>",
        *(
            f'<li><a download="{p.name}" href="{_embed(p, "application/pdf")}">{p.name}</a></li>'
            for p in templates.values()
        ),
        *(
            f"<li>{html_text(paper)}: not written, {html_text(why)}</li>"
            for paper, why in skipped.items()
        ),
        "</ul><h2>Robot export</h2>",
        f"<pre>{html_text(json.dumps(picks, indent=1))}</pre>",
        "</body></html>",
    ]
    path = out_dir / "report.html"
    write_atomic(path, "\n".join(parts))
    return path
