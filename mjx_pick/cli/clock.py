"""How long this process has run: the import part of a command's fixed costs."""

from __future__ import annotations

import os
import time

# When set (a wall-clock time, time.time()): where the command the process runs now began.
# A process that runs one command after another -- the GUI's warm worker -- sets it per
# command, so a command's time counts from its own start, not from the process's.
_began: float | None = None

# When the CLI first loaded (the interpreter is then well under a second old), and how
# much older the process may be before its start is not the interpreter's: a shell that
# runs `... && pip install . && mjx-pick ...` under `bash -c` execs the last command in
# its own process, whose start the kernel then dates to the shell's -- before the pip.
_LOADED_S = time.time()
EXEC_GAP_S = 5.0


def begin(wall_s: float | None) -> None:
    """Count :func:`process_age_s` from wall_s (``time.time()``) instead of the process's
    start; None: from the process's start again."""
    global _began
    _began = wall_s


def process_age_s() -> float | None:
    """Seconds since this process started (Linux ``/proc``), or None where unknown; or
    since the command it runs now began (:func:`begin`).

    What a user waits for before ``main`` runs -- the interpreter's start and the
    imports -- is not seen by a timer started in ``main``; the kernel's record of the
    process's start time is. Where that record is more than ``EXEC_GAP_S`` older than
    the CLI's load, the process ran something else before it exec'd the interpreter (a
    shell's last command), and the age counts from the load instead.
    """
    now = time.time()
    if _began is not None:
        return max(0.0, now - _began)
    try:
        with open("/proc/self/stat") as fh:
            # the fields after the command name "(...)": field 22, starttime, is the 20th
            fields = fh.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        age = max(0.0, uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None
    since_load = max(0.0, now - _LOADED_S)
    return since_load if age > since_load + EXEC_GAP_S else age
