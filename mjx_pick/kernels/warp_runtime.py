"""Warp's runtime, started once per process under one lock.

Warp's own ``init`` has no lock: two threads -- a command's early start
(``engine.devices.start_warp``) and a backend or the feasibility kernel -- could each
make a runtime. Every caller in the package starts Warp through :func:`warp`.
"""

from __future__ import annotations

import threading

_START = threading.Lock()


def warp():
    """The ``warp`` module, imported and initialised once in this process (waits while
    another thread starts it)."""
    with _START:
        import warp as wp

        wp.config.quiet = True  # no banner on stdout (Warp before 1.18)
        # Warp 1.18 logs its banner and module loads at INFO; a stricter level is kept
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
        wp.init()
    return wp
