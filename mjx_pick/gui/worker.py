"""The warm worker's side: a long-lived process that runs GUI jobs one after another.

A job started as a new process pays the interpreter's start, the imports (JAX, MuJoCo),
the object's preparation and the compile of the engine's programs before it simulates
anything. A worker pays them once: it stays alive between jobs, so a second job on the
same object and gripper finds its modules imported, its compiled programs in JAX's
in-process caches and starts simulating at once. The server side (start, restart, the
job's handle) is :mod:`mjx_pick.gui.jobs`; this module is what runs inside the worker.

A job is still exactly the CLI command: ``mjx_pick.cli.main(argv)``, with the process
made to look, for that command, as a new CLI process would:

* its output -- Python's and the C libraries' (MuJoCo, XLA) -- goes to the job's log:
  file descriptors 1 and 2 point at the log while it runs, and back at the worker's own
  log after;
* its working directory is the job's (the work folder's ``logs/``), its environment
  the worker's as it was before the job (a ``--no-cache`` sets a variable; it must not
  stay for the next job), and Python's warnings are shown as in a new process: each
  job starts with the worker's warning filters and an empty "already shown" record, so
  a warning the run gives (e.g. few feasible pick-points) reaches every job's log, where
  the page reads it;
* a cancel is a SIGINT to the worker while the job runs, which the CLI turns into a
  clean stop as it would in its own process; between jobs SIGINT is ignored, so a
  cancel that arrives just after a job ended cannot kill the worker or the next job;
* the CLI's fixed-cost timer (``cli.clock``) counts from when the server started the
  job, not from when the worker started;
* a folder the command claimed and did not close (it cannot happen through ``main``,
  which closes its claims on every error) is closed as failed, so its lock is never held
  by an idle worker.

Protocol: one JSON object per line on the worker's stdin -- ``{"id", "argv", "log",
"cwd", "started"}`` -- and one per line on the reply pipe (the file descriptor given on
the command line): ``{"ready": pid}`` once imported, ``{"id", "code", "rss"}`` after each
job (the exit code the CLI process would have had, and the worker's resident memory in
bytes). End of stdin ends the worker.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import traceback
import warnings

# the modules every simulation command needs: imported when the worker starts, so even
# its first job does not wait for them
WARM_IMPORTS = (
    "mjx_pick.cli",
    "mjx_pick.studies.evaluation",
    "mjx_pick.studies.sweeps",
    "mjx_pick.studies.comparison",
    "mjx_pick.studies.robust",
)


def rss_bytes() -> int:
    """This process's resident memory now (Linux ``/proc``; 0 where unknown)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def run_job(argv: list[str], log: str, cwd: str, started: float | None) -> int:
    """Run one CLI command as its own process would; returns its exit code."""
    import importlib

    from mjx_pick.cli import clock, main
    from mjx_pick.core import cache
    from mjx_pick.outputs.rundir import end_claims

    env = dict(os.environ)
    here = os.getcwd()
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    code = 1
    try:
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.chdir(cwd)
        clock.begin(started)
        cache.reset_warnings()  # a bypassed cache is said in every job's log
        warnings.onceregistry.clear()  # "once" warnings: shown again, as in a new process
        with warnings.catch_warnings():  # the filters back after, "already shown" reset
            signal.signal(signal.SIGINT, signal.default_int_handler)
            try:
                code = int(main(argv) or 0)
            except SystemExit as stop:  # argparse: --help, a bad flag
                if stop.code is None or isinstance(stop.code, int):
                    code = stop.code or 0
                else:  # sys.exit("message"): printed, exit code 1, as Python does
                    print(stop.code, file=sys.stderr)
                    code = 1
            except KeyboardInterrupt:  # a cancel before the CLI installed its handler
                print("mjx-pick: interrupted", file=sys.stderr)
                code = 130
            except BaseException:  # a bug: its traceback, as Python would print it
                traceback.print_exc()
                code = 1
            finally:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
        end_claims("failed", "the run ended without closing its folder")
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        clock.begin(None)
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for f in (fd, *saved):
            os.close(f)
        os.chdir(here)
        os.environ.clear()
        os.environ.update(env)
        importlib.invalidate_caches()
    return code


def serve(reply_fd: int) -> None:
    """The worker's loop: read jobs from stdin, run each, answer on reply_fd."""
    import importlib

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # only a running job takes a cancel
    for name in WARM_IMPORTS:
        importlib.import_module(name)
    reply = os.fdopen(reply_fd, "w", buffering=1)
    reply.write(json.dumps({"ready": os.getpid()}) + "\n")
    for line in sys.stdin:
        if not line.strip():
            continue
        job = json.loads(line)
        try:
            code = run_job(job["argv"], job["log"], job["cwd"], job.get("started"))
        except Exception as err:  # its log or folder unusable: this job fails, not the worker
            code = 1
            try:
                with open(job["log"], "a") as fh:
                    fh.write(f"\nmjx-pick: error: the job could not start: {err}\n")
            except OSError:
                pass
        reply.write(json.dumps({"id": job["id"], "code": code, "rss": rss_bytes()}) + "\n")
