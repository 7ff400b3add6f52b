"""``mjx-pick``: the command line.

Details: docs/outputs.md (cli/__init__.py).
"""

from __future__ import annotations

import logging
import os
import sys
import warnings

from mjx_pick.cli.clock import process_age_s
from mjx_pick.cli.parser import build_parser, refused
from mjx_pick.core import cache
from mjx_pick.core.config import ConfigError
from mjx_pick.engine import interrupts, registry
from mjx_pick.outputs.display import use_offscreen_rendering
from mjx_pick.outputs.rundir import end_claims, error_message

__all__ = ["build_parser", "main"]


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever sys.stderr is at each message (a test's capture, a redirect
    made after the CLI started), not to the stream of the moment it was made."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


def show_steps() -> None:
    """The library's step messages (``mjx_pick.*`` loggers at INFO: a mesh being read,
    decomposed, a silhouette rasterised) on stderr, so a step that takes a while is
    never silent; a library user's own logging setup is left alone."""
    logger = logging.getLogger("mjx_pick")
    if not logger.handlers:
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("mjx-pick: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)


def _warning_line(message, category, filename, lineno, line=None) -> str:
    """A Python warning as the CLI says it: one line, no source file or line of code
    (a user reads the message; its origin is the package's business). A warning from
    another library names its kind."""
    kind = "" if issubclass(category, UserWarning) else f"{category.__name__}: "
    return f"mjx-pick: warning: {kind}{message}\n"


def main(argv: list[str] | None = None) -> int:
    # before anything imports MuJoCo -- parsing a settings flag imports its settings
    # module, and some import MuJoCo: animations on a headless host
    use_offscreen_rendering()
    warnings.formatwarning = _warning_line
    args = build_parser().parse_args(argv)
    args.started_s = process_age_s()  # the interpreter's start and the CLI's imports
    show_steps()
    if getattr(args, "no_cache", False):
        # the one switch the cache reads; child processes (GUI jobs, local Ray) inherit it
        os.environ[cache.ENV_SWITCH] = "0"
    note = registry.ENTRIES.get(getattr(args, "backend", None))
    if note is not None and note.note:  # a limit of a backend chosen by name
        print(f"mjx-pick: note: --backend {note.name} is {note.note}", file=sys.stderr)
    try:
        # a Ctrl-C is never swallowed, and SIGTERM stops a run as it does (see interrupts)
        with interrupts.catching_sigint():
            refused(args)  # every number out of its range, before any work
            return int(args.func(args) or 0)
    except ConfigError as err:
        end_claims("failed", error_message(err))
        print(f"mjx-pick: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:
        status, message = interrupts.stop_status(stop)
        end_claims(status, message)
        out = getattr(args, "out", None)
        hint = (
            f"; what finished is kept: run the same command with --resume to continue in {out}"
            if out and hasattr(args, "resume")
            else ""
        )
        what = "terminated (SIGTERM)" if status == "terminated" else "interrupted"
        print(f"mjx-pick: {what}{hint}", file=sys.stderr)
        return 143 if status == "terminated" else 130
    except OSError as err:  # a disk that fills, a folder made read-only mid-run
        end_claims("failed", error_message(err))
        where = f"{err.filename}: " if err.filename else ""
        print(f"mjx-pick: error: {where}{err.strerror or err}", file=sys.stderr)
        return 1
    except BaseException as err:  # a bug: its traceback, but no folder left "running"
        end_claims("failed", error_message(err))
        raise


if __name__ == "__main__":
    sys.exit(main())
