"""Time to answer in the GUI: the one-pick test simulation and a batch job, first and
second time, as a user clicks them (headless Chromium through Playwright).

Starts ``mjx-pick gui`` on a free port with an empty work folder, imports the shipped
block, then:

* tab 2's test simulation of the default pick-point, twice: seconds from the click to
  the score on the page;
* tab 3's batch of ``--n`` pick-points (``evaluate``, MuJoCo C), twice with the same
  object and gripper: seconds from the click to "complete" on the page; from the click
  to the start of the simulation counted as the folder's ``results.parquet`` written
  (its modification time) less the summary's ``simulate`` and ``write`` times (an upper
  bound: the engine's per-chunk compile calls, ``compile`` in the summary, are spread
  over the run but counted before it); and from the click to the run's checks done
  (``config.json`` written); and from the click to the first chunk file (watched every
  10 ms), less one chunk's simulation at the run's rate (an estimate of the click to
  simulating);
  whether the job ran in the warm worker (its log says nothing else: the summary's
  ``import`` time is the job's own).

Then, without the browser, ``--rss-jobs`` jobs of ``--n`` pick-points one after another
in one warm worker (``mjx_pick.gui.jobs.Workers``), with the worker's resident memory
after each. Run it from a checkout with ``PYTHONPATH`` set to it; one JSON under
``benchmarks/results/``.

  PYTHONPATH=$PWD python benchmarks/probes/gui_time_to_answer.py --n 200 --rss-jobs 10
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))


def checked_delay(out: Path, clicked: float) -> float:
    """Seconds from the click to the run's checks done (its config.json written: the
    imports, the object, the pick-points and their checks behind it; the engine's build
    and the first chunk's compile ahead)."""
    return round((out / "config.json").stat().st_mtime - clicked, 2)


def sim_start_delay(out: Path, clicked: float) -> float | None:
    """Seconds from the click to the start of the simulation of run folder out."""
    summary = json.loads((out / "summary.json").read_text())
    t = summary.get("time_s") or {}
    written = (out / "results.parquet").stat().st_mtime
    return round(written - t.get("simulate", 0.0) - t.get("write", 0.0) - clicked, 2)


INFO = "document.querySelector('[data-testid=test-info]')"
TRACK_INFO = (
    "() => { window.mjxChanges = 0; new MutationObserver(() => window.mjxChanges++)"
    f".observe({INFO}, {{subtree: true, childList: true, characterData: true}}); }}"
)
INFO_ANSWERED = f"() => window.mjxChanges >= 1 && {INFO}.innerText.includes('score')"


def first_chunk_time(out: Path, timeout_s: float = 600.0) -> float:
    """When the run's first chunk file appeared (watched every 10 ms from the click):
    the start of the simulation is one chunk's simulation before it."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if any((out / "chunks").glob("part-*.parquet")) or (out / "results.parquet").exists():
            return time.time()
        time.sleep(0.01)
    raise TimeoutError(f"{out}: no chunk in {timeout_s} s")


def gui_rows(n: int, work: Path) -> list[dict]:
    from playwright.sync_api import sync_playwright
    from test_gui import chromium_path, import_shipped, start_server, stop_server, wait_job

    url, proc = start_server(work, work.parent / "server.log")
    rows = []
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium_path(), args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1500, "height": 1000})
            page.set_default_timeout(300_000)
            page.goto(url)
            import_shipped(page)
            page.get_by_text("2 Set gripper parameters").click()
            for k in (1, 2):
                # the answer is the same text both times: count the changes of the
                # field, so the wait ends on this click's answer, not the last one's
                page.evaluate(TRACK_INFO)
                t0 = time.time()
                page.get_by_test_id("test-pick").click()
                page.wait_for_function(INFO_ANSWERED, polling=50)
                rows.append(
                    {
                        "what": "test pick",
                        "time": k,
                        "click_to_answer_s": round(time.time() - t0, 2),
                    }
                )
            page.get_by_text("3 Generate input data").click()
            box = page.get_by_label("pick-points", exact=True)
            box.fill(str(n))
            box.blur()
            for k in (1, 2):
                name = f"bench-{k}"
                page.get_by_label("run folder name").fill(name)
                out = work / name
                t0 = time.time()
                page.get_by_test_id("start-batch").click()
                first = first_chunk_time(out)
                status = wait_job(page, f"evaluate {name}", 600_000)
                done = time.time()
                summary = json.loads((out / "summary.json").read_text())
                config = json.loads((out / "config.json").read_text())
                chunk_s = config["chunk_size"] / summary["picks_per_s"]
                log = (work / "logs" / f"{name}.log").read_text()
                rows.append(
                    {
                        "what": f"evaluate {n}",
                        "time": k,
                        "click_to_complete_s": round(done - t0, 2),
                        "click_to_simulating_s": sim_start_delay(out, t0),
                        "click_to_checked_s": checked_delay(out, t0),
                        "click_to_first_chunk_s": round(first - t0, 2),
                        "chunk_s": round(chunk_s, 2),
                        "click_to_simulating_est_s": round(first - t0 - chunk_s, 2),
                        "status": status,
                        "time_s": json.loads((out / "summary.json").read_text())["time_s"],
                        "log_tail": log.strip().splitlines()[-3:],
                    }
                )
            browser.close()
    finally:
        stop_server(proc)
    return rows


def rss_rows(n: int, jobs_n: int, work: Path, backend: str, cold: bool) -> list[dict]:
    """jobs_n evaluate jobs of n pick-points one after another, in one warm worker of
    backend -- or, with cold, each in a process of its own (the GUI without workers)."""
    from mjx_pick.gui import jobs

    workers = None
    w = None
    if not cold:
        workers = jobs.Workers(work / "logs")
        workers.prepare(backend)
        w = workers.worker(backend)
        w.ready.wait(300)
    rows = []
    try:
        for k in range(jobs_n):
            out = work / f"rss-{k}"
            argv = ["evaluate", "block", "--n", str(n), "--seed", str(k), "--backend", backend]
            argv += ["--no-progress", "--out", str(out)]
            t0 = time.time()
            job = jobs.Job(argv, work / "logs" / f"rss-{k}.log", out, n, n).start(workers)
            code = job.wait()
            rows.append(
                {
                    "job": k + 1,
                    "backend": backend,
                    "warm": job.warm,
                    "code": code,
                    "time_s": json.loads((out / "summary.json").read_text()).get("time_s"),
                    "click_to_complete_s": round(time.time() - t0, 2),
                    "click_to_simulating_s": sim_start_delay(out, t0),
                    "click_to_checked_s": checked_delay(out, t0),
                    "rss_mb": round(w.rss[-1] / 2**20, 1) if w is not None and w.rss else None,
                }
            )
            print(rows[-1], flush=True)
    finally:
        if workers is not None:
            workers.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--rss-jobs", type=int, default=10)
    ap.add_argument("--no-gui", action="store_true", help="only the worker's memory rows")
    ap.add_argument("--rss-backend", default="mujoco", help="the backend of those jobs")
    ap.add_argument("--cold", action="store_true", help="those jobs each in its own process")
    args = ap.parse_args()
    commit = (
        os.environ.get("MJX_PICK_COMMIT")
        or subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
        ).stdout.strip()
    )
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "work"
        work.mkdir()
        gui = [] if args.no_gui else gui_rows(args.n, work)
        for row in gui:
            print(row, flush=True)
        rss = []
        if args.rss_jobs:
            rss = rss_rows(args.n, args.rss_jobs, Path(tmp) / "rss", args.rss_backend, args.cold)
    result = {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "commit": commit,
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "command": " ".join(sys.argv),
        "gui": gui,
        "rss": rss,
    }
    folder = ROOT / "benchmarks" / "results"
    folder.mkdir(exist_ok=True)
    tag = "" if args.no_gui else "_gui"
    tag += f"_{args.rss_backend}{'_cold' if args.cold else ''}" if args.rss_jobs else ""
    path = folder / f"gui_time_to_answer_{commit}{tag}.json"
    path.write_text(json.dumps(result, indent=1))
    print(f"written {path}")


if __name__ == "__main__":
    main()
