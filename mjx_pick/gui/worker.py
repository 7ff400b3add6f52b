"""The warm worker's side: a long-lived process that runs GUI jobs one after another.

Details: docs/gui.md (gui/worker.py).
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
