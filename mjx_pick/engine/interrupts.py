"""Ctrl-C that is never lost.

Python turns SIGINT into a ``KeyboardInterrupt`` raised wherever the main thread is.
When that is inside a garbage-collector callback (JAX registers one,
``_xla_gc_callback``), Python reports the exception as "ignored" and goes on: a user's
Ctrl-C -- or the GUI's cancel, which is a SIGINT to the CLI child -- was seen to vanish
and the run to finish "complete". So the CLI installs :func:`catching_sigint`: its
handler raises as Python's own does and also records the request, which the engine
reads between chunks (:func:`raise_if_requested`) -- if the first exception was
swallowed, the run still stops at the next chunk, marked "interrupted", its finished
chunks kept for ``--resume``.

The record is process-wide because a signal is; it is cleared when the context ends.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

_requested = threading.Event()


def request() -> None:
    """Record a Ctrl-C (what the SIGINT handler does besides raising)."""
    _requested.set()


def requested() -> bool:
    """Whether a Ctrl-C was recorded since the last :func:`clear`."""
    return _requested.is_set()


def clear() -> None:
    """Forget a recorded Ctrl-C."""
    _requested.clear()


def raise_if_requested() -> None:
    """Raise ``KeyboardInterrupt`` when a Ctrl-C was recorded (it may have been
    swallowed where it was first raised)."""
    if _requested.is_set():
        raise KeyboardInterrupt


def _on_sigint(signum, frame) -> None:
    request()
    raise KeyboardInterrupt


@contextlib.contextmanager
def catching_sigint() -> Iterator[None]:
    """Inside it, SIGINT raises ``KeyboardInterrupt`` and is also recorded (see the
    module docstring). Outside the main thread (where Python allows no handler) it
    changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        clear()
