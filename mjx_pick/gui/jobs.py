"""Long runs started from the GUI: the CLI command itself, in a child process.

Details: docs/gui.md (gui/jobs.py).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from mjx_pick.engine.registry import AUTO, Impl
from mjx_pick.gui import workfolder
from mjx_pick.gui.formatting import library_of, unexpected_text

CANCEL_GRACE_S = 15.0  # after a SIGINT, how long a run may take to write and stop
# The child runs the very package this server runs, and nothing else from where it or the
# server was started. Python's isolated mode leaves the working directory (-P) and
# PYTHONPATH (-E) off sys.path, so a folder named like the package (or like one of its
# dependencies) in the server's working directory is never imported; the package is then
# loaded from the folder the server imported it from (argv[1]), which is not put on
# sys.path either. The user's site-packages stay as the server has them (-s only if the
# server runs without): a `pip install --user` keeps its dependencies. -u: unbuffered
# output (PYTHONUNBUFFERED is ignored under -E), so the log shows progress as it happens.
# Python's Ctrl-C handler is installed whatever the child inherited: a server started in
# the background of a non-interactive shell (a service, `... &`) ignores SIGINT, children
# inherit that, and Python then installs no KeyboardInterrupt at all -- cancel would be a
# no-op (seen: a 200-pick run ran to its end after the SIGINT)
_CLI_FROM_PACKAGE = """\
import importlib.util, pathlib, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
pkg = pathlib.Path(sys.argv[1])
spec = importlib.util.spec_from_file_location(
    "mjx_pick", pkg / "__init__.py", submodule_search_locations=[str(pkg)]
)
module = importlib.util.module_from_spec(spec)
sys.modules["mjx_pick"] = module
spec.loader.exec_module(module)
from mjx_pick.cli import main
sys.exit(main(sys.argv[2:]))
"""


def package_dir() -> Path:
    """The folder of the mjx_pick package this process runs (what a run's child loads)."""
    import mjx_pick

    return Path(mjx_pick.__file__).resolve().parent


def child_argv(argv: list[str]) -> list[str]:
    """The child process's command line for the CLI arguments argv (see _CLI_FROM_PACKAGE)."""
    return _isolated(_CLI_FROM_PACKAGE, argv)


def _isolated(code: str, argv: list[str]) -> list[str]:
    """python in isolated mode running code with the package folder and argv after it."""
    isolated = ["-E", "-P"] + (["-s"] if sys.flags.no_user_site else [])
    return [sys.executable, *isolated, "-u", "-c", code, str(package_dir()), *argv]


# The warm worker: the package loaded as for a job (see _CLI_FROM_PACKAGE), then its loop
# (mjx_pick.gui.worker.serve) with the reply pipe's file descriptor
_WORKER_FROM_PACKAGE = _CLI_FROM_PACKAGE.replace(
    "from mjx_pick.cli import main\nsys.exit(main(sys.argv[2:]))\n",
    "from mjx_pick.gui.worker import serve\nserve(int(sys.argv[2]))\n",
)
assert _WORKER_FROM_PACKAGE != _CLI_FROM_PACKAGE

# the commands a worker runs: the simulation commands, whose fixed costs it saves. Not
# `report` (its cost is rendering, not compiling; its GL contexts are better ended with
# a process) nor `calibrate` (its derivative programs are large and used once).
WARM_COMMANDS = ("evaluate", "sweep", "compare", "robust", "validate")
DEFAULT_BACKEND = Impl.MUJOCO.value  # the settings form's; its worker is started with the server
# a worker whose resident memory grew by more than this since its first job is replaced
# before its next job (a leak in a library must not grow the machine's memory job after
# job)
WORKER_GROWTH_BYTES = 1 << 30


def warm_backend(argv: list[str]) -> str | None:
    """The backend whose worker may run the CLI command argv, or None when it runs in a
    process of its own (a command a worker does not run, a run on a Ray cluster)."""
    if not argv or argv[0] not in WARM_COMMANDS or "--ray" in argv or "--help" in argv:
        return None
    if "--backend" in argv[:-1]:
        return argv[argv.index("--backend") + 1]
    return AUTO


class Worker:
    """One warm worker process for one backend (see :mod:`mjx_pick.gui.worker`)."""

    def __init__(self, backend: str, folder: Path):
        """folder: where its own log goes (the work folder's logs/)."""
        self.backend, self.folder = backend, Path(folder)
        self.log = self.folder / f"worker-{backend}.log"
        self.proc: subprocess.Popen | None = None
        self.current: WorkerRun | None = None  # the job it runs now
        self.ready = threading.Event()  # imported and listening
        self.replies_read = threading.Event()  # its reply pipe closed and read to the end
        self.pid: int | None = None
        self.rss: list[int] = []  # its resident memory after each job, bytes
        self.jobs = 0
        self.on_death = None  # called when it is found dead after a job it ran
        self._lock = threading.Lock()
        self._ids = 0

    def start(self) -> Worker:
        self.folder.mkdir(parents=True, exist_ok=True)
        read, write = os.pipe()
        # JAX takes three quarters of a GPU's memory at its first use and keeps it; a job's
        # own process gave it back when it ended, a worker lives on: it allocates as needed
        env = {**os.environ, "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}
        with self.log.open("ab") as fh:
            self.proc = subprocess.Popen(
                _isolated(_WORKER_FROM_PACKAGE, [str(write)]),
                env=env,
                stdin=subprocess.PIPE,
                stdout=fh,
                stderr=subprocess.STDOUT,
                cwd=self.folder,
                pass_fds=(write,),
                # its own process group: a Ctrl-C at the server's terminal goes to the
                # server, which cancels the running job itself, and never to an idle worker
                start_new_session=True,
            )
        os.close(write)
        self.pid = self.proc.pid
        threading.Thread(target=self._read, args=(read,), daemon=True).start()
        return self

    def _read(self, fd: int) -> None:
        """The reply pipe: ready, then one line per finished job (a thread)."""
        with os.fdopen(fd) as replies:
            for line in replies:
                try:
                    msg = json.loads(line)
                except ValueError:
                    continue
                if "ready" in msg:
                    self.ready.set()
                    continue
                with self._lock:
                    run = self.current
                    if run is not None and run.id == msg.get("id"):
                        self.rss.append(int(msg.get("rss") or 0))
                        self.jobs += 1
                        self.current = None
                        run.code = int(msg["code"])
        self.replies_read.set()

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    @property
    def busy(self) -> bool:
        return self.current is not None

    @property
    def grown(self) -> bool:
        """Its memory grew by more than WORKER_GROWTH_BYTES since its first job."""
        return len(self.rss) >= 2 and self.rss[-1] - self.rss[0] > WORKER_GROWTH_BYTES

    def run(self, argv: list[str], log: Path) -> WorkerRun:
        """Hand it the CLI command argv, its output appended to log."""
        with self._lock:
            if self.current is not None:
                raise RuntimeError(f"the {self.backend} worker is running another job")
            self._ids += 1
            run = WorkerRun(self, self._ids, Path(log))
            self.current = run
        job = {
            "id": run.id,
            "argv": list(argv),
            "log": str(log),
            "cwd": str(Path(log).parent),
            "started": time.time(),
        }
        try:
            self.proc.stdin.write((json.dumps(job) + "\n").encode())
            self.proc.stdin.flush()
        except OSError:  # it died: the run's poll reports it
            pass
        return run

    def stop(self) -> None:
        """End it: end of input when idle (it exits), a kill if it does not in 5 s."""
        if self.proc is None:
            return
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def ended_how(self) -> str:
        """How its process ended, in words ("killed by signal 9 (SIGKILL)", "exit code 1")."""
        code = self.proc.poll() if self.proc is not None else None
        if code is None:
            return "still running"
        if code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = "?"
            return f"killed by signal {-code} ({name})"
        return f"exit code {code}"


class WorkerRun:
    """A job running in a worker, with the calls of the ``subprocess.Popen`` a job's
    own process would have (poll, wait, send_signal, kill), so :class:`Job` treats both
    alike."""

    def __init__(self, worker: Worker, id_: int, log: Path):
        self.worker, self.id, self.log = worker, id_, log
        self.code: int | None = None  # the CLI's exit code, once the worker answered
        self.crashed = False  # the worker died during the job

    @property
    def pid(self) -> int | None:
        return self.worker.pid

    def poll(self) -> int | None:
        if self.code is not None:
            return self.code
        if self.worker.alive:
            return None
        self.worker.proc.wait()
        self.worker.replies_read.wait(5)  # an answer it sent before it ended is read
        if self.code is not None:  # it answered, then exited
            return self.code
        self.crashed = True
        how = self.worker.ended_how()
        self.code = self.worker.proc.returncode or 1
        with self.log.open("a") as fh:  # the page shows this line (Job.error_message)
            fh.write(
                f"\nmjx-pick: error: the worker process that ran this job stopped ({how}, "
                f"pid {self.worker.pid}); a new one is started for the next job\n"
            )
        with self.worker._lock:  # noqa: SLF001 - the worker's own state
            self.worker.current = None
        if self.worker.on_death is not None:
            self.worker.on_death()
        return self.code

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.poll()) is None:
            if deadline is not None and time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(f"job {self.id}", timeout)
            time.sleep(0.05)
        return code

    def send_signal(self, sig: int) -> None:
        """A signal for the job: sent to the worker only while it still runs this job."""
        if self.poll() is None:
            try:
                os.kill(self.worker.pid, sig)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        """The job ignores its cancel: the worker goes with it (replaced for the next job)."""
        if self.poll() is None:
            self.worker.proc.kill()


class Workers:
    """The server's warm workers, one per backend, started with the first job for it."""

    def __init__(self, folder: Path):
        """folder: where the workers' own logs go (the work folder's logs/)."""
        self.folder = Path(folder)
        self._by_backend: dict[str, Worker] = {}
        self._lock = threading.Lock()
        self.notes: list[str] = []  # what happened to workers, for the server's page

    def worker(self, backend: str) -> Worker | None:
        """The running worker of backend (None if there is none)."""
        return self._by_backend.get(backend)

    def take(self, argv: list[str]) -> Worker | None:
        """The idle, live worker that runs argv (started now if the backend has none,
        replaced if it died or grew), or None: argv runs in its own process."""
        backend = warm_backend(argv)
        if backend is None:
            return None
        # a busy worker's job is polled outside the lock: a worker that died in it calls
        # back (on_death -> prepare), which takes the lock and may start its successor
        w = self._by_backend.get(backend)
        running = w.current if w is not None else None
        if running is not None and running.poll() is None:
            return None  # busy with another tab's job: a process of its own
        with self._lock:
            w = self._by_backend.get(backend)  # after that poll: perhaps a successor
            if w is not None and w.busy:
                return None
            if w is not None and not w.alive:
                self.notes.append(
                    f"the {backend} worker (pid {w.pid}) had stopped ({w.ended_how()}); "
                    "a new one was started"
                )
                w.stop()
                w = None
            elif w is not None and w.grown:
                self.notes.append(
                    f"the {backend} worker (pid {w.pid}) was replaced: its memory grew by "
                    f"{(w.rss[-1] - w.rss[0]) / 2**20:.0f} MB over {w.jobs} jobs"
                )
                w.stop()
                w = None
            if w is None:
                w = self._start(backend)
        # a worker still importing is not waited for (the page's event loop runs this):
        # the job runs in its own process and the worker is warm for the next one
        if not w.ready.is_set() or not w.alive:
            return None
        return w

    def _start(self, backend: str) -> Worker:
        w = Worker(backend, self.folder)
        w.on_death = lambda: self.prepare(backend)  # died in a job: warm for the next
        self._by_backend[backend] = w.start()
        return w

    def prepare(self, backend: str) -> None:
        """Start backend's worker now (it imports in the background), so a job finds it
        warm; nothing if it has a live one."""
        with self._lock:
            w = self._by_backend.get(backend)
            if w is None or not w.alive:
                if w is not None:
                    w.stop()  # its pipe closed, its process reaped
                self._start(backend)

    def close(self) -> None:
        """Stop every worker (the server stops)."""
        with self._lock:
            workers, self._by_backend = list(self._by_backend.values()), {}
        for w in workers:
            w.stop()


class Runs:
    """The runs this server started: server-side state, shared by every page.

    A page is one load of one browser tab; the runs outlive it. A reloaded tab finds
    the run it started (by its browser tab's id), a second tab sees the others, and the
    server stops the running ones when it stops.
    """

    def __init__(self, workers: Workers | None = None) -> None:
        """workers: the warm workers jobs may run in (None: each in its own process)."""
        self._jobs: list[Job] = []
        self.workers = workers

    def recover(self, workdir: Path) -> int:
        """Add the runs of the work folder's run folders (:func:`recovered_runs`) that
        this server does not know yet, oldest first: what a restarted server remembers.
        Returns how many."""
        known = {j.out.resolve() for j in self._jobs if j.out is not None}
        found = [j for j in recovered_runs(workdir) if j.out.resolve() not in known]
        self._jobs[:0] = found
        return len(found)

    def add(self, job: Job, owner: str | None) -> None:
        job.owner = owner
        self._jobs.append(job)

    def forget(self, job: Job) -> None:
        """A run that never started (the CLI refused it as long, before any work, and
        the page asks instead): no longer listed."""
        if job in self._jobs:
            self._jobs.remove(job)

    def __iter__(self):
        return iter(list(self._jobs))

    def last_of(self, owner: str | None) -> Job | None:
        """The newest run the browser tab owner started, running or ended."""
        mine = [j for j in self._jobs if owner is not None and j.owner == owner]
        return mine[-1] if mine else None

    def taken(self, job: Job, owner: str | None) -> str:
        """Why job cannot start now ('' if it can): a run of this server, of this or
        another browser tab, writes the folder it would write. Asked as it starts, in
        the server's one event loop: two tabs that checked a run name at the same moment
        (each waiting for its pick-point count meanwhile) cannot both start it -- the
        second would show the first's progress until its own process found the folder
        locked."""
        if job.writes is None:
            return ""
        folder = job.writes.resolve()
        for other in reversed(self._jobs):
            if other.running and other.writes is not None and other.writes.resolve() == folder:
                whose = "this" if owner is not None and other.owner == owner else "another"
                return (
                    f"{job.writes.name}: '{other.title}' ({whose} browser tab's) is writing "
                    "this folder now: wait for it to end, or choose another run folder name"
                )
        return ""

    def writing(self, folder: Path) -> Job | None:
        """The run of this server still writing folder, if any."""
        folder = Path(folder).resolve()
        for job in reversed(self._jobs):
            if job.running and job.out is not None and job.out.resolve() == folder:
                return job
        return None


@dataclasses.dataclass
class Progress:
    """What the page shows about a run."""

    state: str  # running | complete | cancelled | failed
    done: int | None  # pick-points finished (None: unknown, e.g. a sweep)
    total: int | None
    rate: float | None  # pick-points per second
    eta_s: float | None
    elapsed_s: float
    message: str = ""
    unit: str = "pick-points"
    warnings: tuple[str, ...] = ()  # the run's warnings (e.g. few feasible pick-points)

    @property
    def fraction(self) -> float | None:
        if self.done is None or not self.total:
            return None
        return min(1.0, self.done / self.total)


class Job:
    """One CLI command running in a child process, its log in ``log``."""

    def __init__(
        self,
        argv: list[str],
        log: Path,
        out: Path | None = None,
        total: int | None = None,
        chunk: int | None = None,
        steps_logged: str | None = None,
        unit: str = "pick-points",
        counted: str | None = None,
    ):
        """total, chunk: pick-points and chunk size of an evaluate run (progress from its
        chunk files); steps_logged: a regular expression whose group 1 is the number of
        the last finished step in the run's output (calibrate's "step 12 loss ..."),
        with total the number of steps; counted: a regular expression whose groups 1
        and 2 are the units done and in all in the run's progress lines (the CLI's
        progress bar in a log: "report:  40% 4/10 part ...")."""
        self.argv = list(argv)
        self.asked_log = Path(log)  # the log's name as asked (a taken one gets -2, -3)
        self.steps_logged = re.compile(steps_logged) if steps_logged else None
        self.counted = re.compile(counted) if counted else None
        self.unit = unit
        self.log = Path(log)
        self.out = Path(out) if out is not None else None
        self.writes = self.out  # the folder it writes (a report: its run's, not its own)
        self.total = total
        self.chunk = chunk
        self._proc: subprocess.Popen | WorkerRun | None = None
        self._t0 = 0.0
        self._started_wall: float | None = None  # when it started, s since the epoch
        self._cancelled_at: float | None = None
        self._chunks_before: set[str] = set()
        self._done = 0  # the most pick-points seen done: a count never goes back
        self.title = " ".join(argv[:1])  # what the page calls it (set when it starts)
        self.elapsed_s: float | None = None  # a run that ended before this server started
        self.notes: tuple[str, ...] = ()  # the warm workers' news when it started
        self.owner: str | None = None  # the browser tab that started it

    def again(self, *extra: str) -> Job:
        """This run once more, with extra CLI arguments (``--yes`` once a long run is
        confirmed): the same folder, count and progress; its log beside this one's."""
        job = Job(self.argv + list(extra), self.asked_log, self.out, self.total, self.chunk)
        job.steps_logged, job.counted, job.unit = self.steps_logged, self.counted, self.unit
        job.writes = self.writes
        return job

    def refused_as_long(self) -> str:
        """The CLI's refusal of this run as too long to start unasked (its estimate,
        ``studies.duration.refuse_long``), when that is how it ended; else ''. A run
        given --yes is never refused so."""
        if "--yes" in self.argv or self._proc is None or self._proc.poll() in (None, 0):
            return ""
        found = LONG_REFUSAL.findall(self._log_text())
        return found[-1].strip() if found else ""

    def discard_log(self) -> None:
        """Remove this run's log: a run the CLI refused before any work (as long, and the
        page asks instead) leaves no trace that would take its name (a run's name is its
        log's and its folder's, and a taken one is refused)."""
        try:
            workfolder.confined(self.log, self.workdir)
            self.log.unlink(missing_ok=True)  # the log itself: a link, never its target
        except (OSError, ValueError):  # outside the work folder (a link): left alone
            pass

    @property
    def command_line(self) -> str:
        """The same run typed at a shell."""
        return shlex.join(["mjx-pick", *self.argv])

    @property
    def workdir(self) -> Path:
        """The work folder it runs in: its log is ``logs/<name>.log`` there, and the
        page reads its files only inside it (:mod:`mjx_pick.gui.workfolder`)."""
        return self.log.parent.parent

    def start(self, workers: Workers | None = None) -> Job:
        """Start the run -- in a warm worker of workers when one serves it, else in a
        process of its own; its log never replaces another run's (a taken name gets -2,
        -3)."""
        self.log = unused_path(self.log)
        self._chunks_before = {f.name for f in self._chunks()}
        self._t0 = time.monotonic()
        self._started_wall = time.time()
        with self.log.open("wb") as fh:
            fh.write(f"$ {self.command_line}\n".encode())
        worker = workers.take(self.argv) if workers is not None else None
        if workers is not None:  # what happened to a worker: in the log and on the page
            self.notes = tuple(workers.notes)
            workers.notes.clear()
            with self.log.open("a") as fh:
                for note in self.notes:
                    fh.write(f"mjx-pick: note: {note}\n")
        if worker is not None:
            self._proc = worker.run(self.argv, self.log)
            return self
        with self.log.open("ab") as fh:
            # every path in argv is absolute: the working directory is the logs folder,
            # never the one the server was started from
            self._proc = subprocess.Popen(
                child_argv(self.argv),
                stdout=fh,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                cwd=self.log.parent,
            )
        return self

    @property
    def where(self) -> str:
        """Where the run runs, in the page's words."""
        if isinstance(self._proc, WorkerRun):
            w = self._proc.worker
            return (
                f"in the warm {w.backend} worker (pid {w.pid}, its job {self._proc.id}): "
                "imports and compiled programs kept from its earlier jobs"
            )
        if isinstance(self._proc, FolderRun):
            return "a run of this work folder from before the server started"
        return "in a process of its own"

    @property
    def warm(self) -> bool:
        """Whether the run went to a warm worker (not a process of its own)."""
        return isinstance(self._proc, WorkerRun)

    @property
    def started_here(self) -> bool:
        """Whether this server started the run (not one recovered from its folder)."""
        return not isinstance(self._proc, FolderRun)

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def cancel(self) -> None:
        """Ask the run to stop as Ctrl-C would; it keeps what finished."""
        if self.running and self._cancelled_at is None:
            self._proc.send_signal(signal.SIGINT)
            self._cancelled_at = time.monotonic()

    def wait(self, timeout: float | None = None) -> int:
        return self._proc.wait(timeout)

    def _ran_s(self, seen_s: float) -> float:
        """How long a run that has ended ran, as its folder records it: from its start
        to its manifest's finish, else to its log's last write -- never to the moment a
        page first polled it after its end (a page reloaded long after saw it grow:
        59 s, then 199 s); seen_s (start to now) where neither says more."""
        from mjx_pick.outputs.rundir import MANIFEST

        if self._started_wall is None:
            return seen_s
        end = _wall((self._read_json(MANIFEST) or {}).get("finished"))
        if end is None or end < self._started_wall:
            try:
                end = workfolder.confined(self.log, self.workdir).stat().st_mtime
            except (OSError, ValueError):
                return seen_s
        return min(seen_s, max(0.0, end - self._started_wall))

    def _chunks(self) -> list[Path]:
        if self.out is None:
            return []
        return list((self.out / "chunks").glob("part-*.parquet"))

    def poll(self) -> Progress:
        """The run's state now; a stopped run that was asked to cancel is killed late."""
        now = time.monotonic()
        elapsed = now - self._t0 if self.elapsed_s is None else self.elapsed_s
        if self._cancelled_at is not None and self.running:
            if now - self._cancelled_at > CANCEL_GRACE_S:
                self._proc.kill()
        code = self._proc.poll() if self._proc is not None else None
        if code is not None and self.elapsed_s is None:  # ended: its duration, once
            self.elapsed_s = elapsed = self._ran_s(now - self._t0)
        done = rate = eta = None
        total = self.total
        message = ""
        if self.chunk and self.total:
            done, total, rate, message = self._evaluate_progress(code == 0)
            if rate and code is None:
                eta = max(0.0, (total - done) / rate)
        if self.steps_logged is not None and self.total:
            found = self.steps_logged.findall(self._log_text())
            done = min(self.total, int(found[-1]) + 1) if found else 0
        if self.counted is not None:
            found = self.counted.findall(self._log_text())
            if found:
                done, total = int(found[-1][0]), int(found[-1][1])
        if code is None:
            state = "running"
            if self._cancelled_at:
                message = "stopping: finishing the current chunk"
            elif not message or message == "checking the pick-points":
                # a long search for feasible poses (any study's) says how far it is
                searching = self._searching()
                if searching:
                    message = f"checking the pick-points: {searching}"
        elif code == 0:
            state, message = "complete", ""
            if total:
                done = total
        elif self._cancelled_at is not None:
            state, message = "cancelled", "cancelled; what finished is kept"
        else:
            state, message = "failed", self.error_message(code)
        return Progress(state, done, total, rate, eta, elapsed, message, self.unit, self.warnings())

    def _evaluate_progress(self, complete: bool):
        """(done, total, rate, message) of an evaluate run, read from its folder.

        total: the feasible pick-points the run simulates (config.json's n, written once
        the checks are done; until then the number asked for); done: finished chunks
        times the chunk size, never less than shown before (a complete run removes its
        chunks); rate: pick-points per second of simulation -- the summary's once the run
        is complete, before that the same measured between finished chunks (the first
        chunk, which includes compiling, only starts the clock)."""
        config = self._read_json("config.json")
        total, chunk = self.total, self.chunk
        if config is not None and config.get("n"):
            total, chunk = int(config["n"]), int(config.get("chunk_size") or chunk)
        files = self._chunks()
        self._done = min(total, max(self._done, len(files) * chunk))
        message = ""
        if config is None:
            message = "checking the pick-points"
        elif not files:
            message = "simulating the first chunk (compiling first)"
        rate = None
        if complete:
            summary = self._read_json("summary.json") or {}
            rate = summary.get("picks_per_s")
            self._done = total
        else:
            new = sorted(
                t for f in files if f.name not in self._chunks_before for t in _mtimes([f])
            )
            if len(new) >= 2 and new[-1] > new[0]:
                rate = (len(new) - 1) * chunk / (new[-1] - new[0])
        return self._done, total, rate, message

    def _searching(self) -> str:
        """The progress line of a search for feasible pick-points the run is in now
        (the last line of its log is one), or ''."""
        lines = self._log_text().rstrip().splitlines()
        found = _SEARCH_NOTE.match(lines[-1]) if lines else None
        return found.group(1) if found else ""

    def warnings(self) -> tuple[str, ...]:
        """The run's warnings (Python's, in its log), each once, without the file and
        line; after what happened to a warm worker before it started (one found dead)."""
        seen: list[str] = list(self.notes)
        for m in _WARNING.finditer(self._log_text()):
            text = m.group(1).strip()
            if text not in seen:
                seen.append(text)
        return tuple(seen)

    def _log_text(self) -> str:
        """Its log ('' while there is none, or where a link leads it outside)."""
        try:
            return workfolder.read_text(self.log, self.workdir)
        except (OSError, ValueError):
            return ""

    def _read_json(self, name: str) -> dict | None:
        """A JSON file of its folder, or None (none yet, not whole, or outside)."""
        if self.out is None:
            return None
        return workfolder.json_or_none(self.out / name, self.workdir)

    def error_message(self, code: int) -> str:
        """One line for the page: the CLI's own error line, else the exception's."""
        from mjx_pick.gui.forms import page_words

        # paths inside the work folder as the page names them (relative to it)
        work = f"{self.log.parent.parent}/"
        lines = self._log_text().replace(work, "").splitlines()
        log = f"{self.log.relative_to(self.log.parent.parent)} in the work folder"
        for line in reversed(lines):
            if "error: " in line and line.startswith("mjx-pick"):
                return page_words(line.split("error: ", 1)[1].strip())
        crashed = _crash(lines)
        if crashed is not None:  # what failed and where, never the traceback's text
            library, kind = crashed
            return unexpected_text(f"the run (exit code {code})", library, kind, log)
        return f"the run stopped (exit code {code}) without an error message; its log: {log}"


# the exit code a CLI run that ended with a folder's status had (main's return values)
EXIT_OF_STATUS = {"complete": 0, "interrupted": 130, "cancelled": 130, "terminated": 143}


class FolderRun:
    """A run this server did not start -- one of the work folder's before a restart --
    with the calls of a ``subprocess.Popen`` (poll, wait, send_signal, kill), answered
    from its folder: running while a process holds the folder's lock (a job of the
    previous server's worker or child that is still going), else the exit code its
    manifest's status stands for."""

    def __init__(self, out: Path, workdir: Path):
        self.out, self.workdir = Path(out), Path(workdir)
        self.pid: int | None = None
        self._code: int | None = None  # once ended, it stays so (the page polls often)

    def poll(self) -> int | None:
        if self._code is not None:
            return self._code
        holder = workfolder.lock_holder(self.out, self.workdir)
        if holder is not None:
            # a process of this machine can be signalled; another host's (a work folder
            # on a shared disk) only watched
            here = holder.get("host") in (None, socket.gethostname())
            self.pid = holder.get("pid") if here else None
            return None
        status = (workfolder.manifest(self.out, self.workdir) or {}).get("status")
        self._code = EXIT_OF_STATUS.get(status, 1)  # "failed", or "running" and dead
        return self._code

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.poll()) is None:
            if deadline is not None and time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(str(self.out), timeout)
            time.sleep(0.2)
        return code

    def send_signal(self, sig: int) -> None:
        if self.poll() is None and isinstance(self.pid, int):
            try:
                os.kill(self.pid, sig)
            except (ProcessLookupError, PermissionError):
                pass

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def recovered_runs(workdir: Path) -> list[Job]:
    """A job for each run folder of the work folder (a folder with an mjx-pick
    manifest), oldest first: its command line from its log's first line (``logs/<folder
    name>.log``, as the GUI writes it), its state and progress from its folder."""
    workdir = Path(workdir)
    found = []
    folders, _ = workfolder.run_folders(workdir)  # never one a link leads outside
    for folder in folders:
        manifest = workfolder.manifest(folder, workdir)
        if not manifest or not manifest.get("command"):
            continue
        log = workdir / "logs" / f"{folder.name}.log"
        argv = recorded_argv(log, workdir) or [manifest["command"], "--out", str(folder)]
        total = chunk = None
        if manifest["command"] == "evaluate":
            config = workfolder.json_or_none(folder / "config.json", workdir) or {}
            total, chunk = config.get("n"), config.get("chunk_size")
        if manifest["command"] in STUDY_COMMANDS:
            job = study_job(argv, log, folder)
        else:
            job = Job(argv, log, folder, total, chunk)
        job.title = f"{manifest['command']} {folder.name}"
        job._proc = FolderRun(folder, workdir)
        started, finished = _wall(manifest.get("started")), _wall(manifest.get("finished"))
        job._t0 = time.monotonic() - (time.time() - started if started else 0.0)
        job._started_wall = started
        if started and finished and manifest.get("status") != "running":
            job.elapsed_s = max(0.0, finished - started)  # ended: its own duration
        if manifest.get("status") in ("interrupted", "cancelled", "terminated"):
            job._cancelled_at = job._t0  # shown as cancelled, what finished kept
        found.append((manifest.get("started") or "", job))
    return [job for _, job in sorted(found, key=lambda sj: sj[0])]


def recorded_argv(log: Path, workdir: Path) -> list[str] | None:
    """The CLI arguments a run of the page was started with: its log's first line
    (``$ mjx-pick ...``, as :meth:`Job.start` writes it), or None."""
    try:
        first = workfolder.read_text(log, workdir).split("\n", 1)[0]
        if first.startswith("$ mjx-pick "):
            return shlex.split(first[len("$ mjx-pick ") :])
    except (OSError, ValueError):
        pass
    return None


def flag_value(argv: list[str], flag: str) -> str | None:
    """The value given to flag in argv (``--n 40``), or None."""
    i = len(argv) - 1 - argv[::-1].index(flag) if flag in argv else None
    return argv[i + 1] if i is not None and i + 1 < len(argv) else None


def _wall(stamp: str | None) -> float | None:
    """An ISO time of a manifest as seconds since the epoch (None if absent or bad)."""
    import datetime

    try:
        return datetime.datetime.fromisoformat(stamp).timestamp() if stamp else None
    except ValueError:
        return None


# The CLI's refusal of a run estimated longer than a few minutes on this machine
# (studies.duration.refuse_long): "<what> would take about 8 min (...) on this machine;
# pass --yes to start it, or make it smaller". The page asks instead (JobPanel), and
# passes --yes once the user confirms.
LONG_REFUSAL = re.compile(
    r"(?m)^mjx-pick: error: (.+ would take .+ on this machine; pass --yes .*)$"
)


def long_run(study: str, what: str, backend: str, grasp=None, **sizes) -> str:
    """Why a run of the page is asked about before it starts ('' when it is not): the
    one estimate every interface asks (``studies.duration``: count, estimate,
    refuse_long) of study with sizes (``duration.count``'s) and the procedure grasp
    on backend, on this machine -- refuse_long's words, which the CLI would refuse the
    same run with unless --yes."""
    from mjx_pick.core.config import ConfigError
    from mjx_pick.engine import devices, registry
    from mjx_pick.studies import duration

    gpu = backend == AUTO or registry.ENTRIES[backend].device is registry.Device.NVIDIA_GPU
    if gpu and devices.nvidia_driver_present():
        # counting this machine's GPUs (or resolving 'auto' there) starts Warp's CUDA
        # runtime, which the server never does: the run's own process estimates, and a
        # run it refuses as long is asked about then (JobPanel, LONG_REFUSAL)
        return ""
    est = duration.estimate(duration.count(study, **sizes), grasp, None, backend)
    try:
        duration.refuse_long(est, what, yes=False)
    except ConfigError as err:
        return str(err)
    return ""


# the report's progress lines in its log (outputs.progress.ProgressBar's line mode)
REPORT_PARTS = r"(?m)^report: +\d+% (\d+)/(\d+) part"
# a study's (sweep, compare, robust): "sweep: 2 variants (mujoco):  50% 6/12 sim [...]"
SIMULATED = r"(?m)^\w[^\n]*: +\d+% (\d+)/(\d+) sim \["
STUDY_COMMANDS = ("sweep", "compare", "robust")  # the commands study_job counts


def study_job(argv: list[str], log: Path, out: Path) -> Job:
    """A sweep, compare or robust run writing into out, its progress counted in
    simulations from its log (each tenth done; a study whose total grows as it goes,
    robust's draws after its pick-points, says the total known so far)."""
    return Job(argv, log, out, unit="simulations", counted=SIMULATED)


def report_job(run: Path, n: int, animations: bool, log: Path) -> Job:
    """``mjx-pick report`` of the evaluate folder run (n best and n worst), its progress
    counted in the report's parts (each force plot, each animation -- the slow ones --
    the maps, each template, the robot export, the page) from its log."""
    argv = ["report", str(run), "--n", str(int(n))]
    if not animations:
        argv.append("--no-animations")
    job = Job(argv, log, unit="parts of the report", counted=REPORT_PARTS)
    job.writes = Path(run)  # its pages go into the run's folder: one writer at a time
    return job


def unused_path(path: Path) -> Path:
    """path, or path with -2, -3, ... before its suffix: the first that does not exist
    (created empty here, so two runs started at once cannot take the same one)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    for k in range(1, 10_000):
        p = path if k == 1 else path.with_name(f"{path.stem}-{k}{path.suffix}")
        try:
            p.touch(exist_ok=False)
        except FileExistsError:
            continue
        return p
    raise FileExistsError(f"{path}: too many files of this name")


_WARNING = re.compile(r"(?m)^\S*:\d+: \w*Warning: (.*)$")
_SEARCH_NOTE = re.compile(r"^mjx-pick: (checked [\d,]+ of at most [\d,]+ candidate poses.*)$")
_FRAME = re.compile(r'^\s*File "([^"]+)", line \d+')
_RAISED = re.compile(r"^([A-Za-z_][\w.]*(?:Error|Exception|Interrupt|Exit|Warning))\b")


def _crash(lines: list[str]) -> tuple[str, str] | None:
    """(library, exception type) of the last traceback in a run's log lines, or None."""
    start = max((i for i, ln in enumerate(lines) if ln.startswith("Traceback")), default=None)
    if start is None:
        return None
    frames = [m.group(1) for ln in lines[start:] if (m := _FRAME.match(ln))]
    kind = next(
        (m.group(1).rsplit(".", 1)[-1] for ln in lines[start:] if (m := _RAISED.match(ln))),
        "an exception",
    )
    return (library_of(frames[-1]) if frames else "Python"), kind


def _mtimes(files: list[Path]) -> list[float]:
    """The modification times of files that still exist: a run that completes removes
    its chunk files while the page may be reading them."""
    times = []
    for f in files:
        try:
            times.append(f.stat().st_mtime)
        except FileNotFoundError:
            continue
    return times


def _newest_mtime(files: list[Path]) -> float | None:
    """The newest modification time of files that still exist."""
    return max(_mtimes(files), default=None)


PROGRESS_STEPS = 50  # an evaluate run's bar moves at least every 2 % of its pick-points


def progress_chunk(feasible: int) -> int:
    """Pick-points per saved chunk of an evaluate run of `feasible` pick-points: the bar
    moves once per chunk, so at least PROGRESS_STEPS chunks (a chunk of one at most)."""
    return max(1, math.ceil(feasible / PROGRESS_STEPS))


ESTIMATE_SAMPLE = 2000  # feasible pick-points drawn to estimate a large run's count


def feasible_estimate(
    obj, settings, n: int, seed: int, sample: int = ESTIMATE_SAMPLE, progress=None
) -> int:
    """How many of n asked pick-points an evaluate run will find feasible (it simulates
    only those): exact when n <= sample, else from the feasible fraction of the first
    `sample` candidates and the candidates the generator checks at most. progress:
    ``generate_normal``'s (a :class:`~mjx_pick.gui.search.Search`)."""
    import warnings

    from mjx_pick.core.pickpoints import check_stroke, generate_normal

    with warnings.catch_warnings():  # a short sample: its shortfall says nothing yet
        warnings.simplefilter("ignore")
        # a part no pose fits is refused before the raster and the draws, not once the
        # run's job has started (its log shows the warnings check_stroke gives)
        check_stroke(obj, settings.gripper, settings.picks, settings.grasp)
        picks = generate_normal(
            obj,
            settings.gripper,
            min(n, sample),
            seed,
            settings.picks,
            settings.grasp,
            progress=progress,
        )
    if n <= sample or len(picks) < min(n, sample):
        return len(picks)
    fraction = len(picks) / max(picks.n_candidates, 1)
    return int(min(n, fraction * settings.picks.max_candidates))
