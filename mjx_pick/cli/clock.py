"""How long this process has run: the import part of a command's fixed costs."""

from __future__ import annotations

import os


def process_age_s() -> float | None:
    """Seconds since this process started (Linux ``/proc``), or None where unknown.

    What a user waits for before ``main`` runs -- the interpreter's start and the
    imports -- is not seen by a timer started in ``main``; the kernel's record of the
    process's start time is.
    """
    try:
        with open("/proc/self/stat") as fh:
            # the fields after the command name "(...)": field 22, starttime, is the 20th
            fields = fh.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return max(0.0, uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None
