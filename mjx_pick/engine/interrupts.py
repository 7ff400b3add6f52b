"""Ctrl-C that is never lost.

Details: docs/engine.md (engine/interrupts.py).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

_requested = threading.Event()
_terminated = threading.Event()


class Terminated(KeyboardInterrupt):
    """The process got SIGTERM: stopped like a Ctrl-C, recorded as "terminated"."""


def request(terminate: bool = False) -> None:
    """Record a Ctrl-C, or with terminate a SIGTERM (what the handlers do besides
    raising)."""
    if terminate:
        _terminated.set()
    _requested.set()


def stop_status(stop: BaseException) -> tuple[str, str]:
    """The status and message a run folder records for what stopped its run: a cancel
    event, SIGTERM or Ctrl-C."""
    if isinstance(stop, Terminated):
        return "terminated", "stopped by SIGTERM; its finished chunks are kept for --resume"
    if isinstance(stop, KeyboardInterrupt):
        return "interrupted", "stopped by Ctrl-C; its finished chunks are kept for --resume"
    return "cancelled", "cancelled; its finished chunks are kept for --resume"


def requested() -> bool:
    """Whether a Ctrl-C was recorded since the last :func:`clear`."""
    return _requested.is_set()


def clear() -> None:
    """Forget a recorded Ctrl-C."""
    _requested.clear()
    _terminated.clear()


def raise_if_requested() -> None:
    """Raise ``KeyboardInterrupt`` (:class:`Terminated` for a SIGTERM) when one was
    recorded (it may have been swallowed where it was first raised)."""
    if _terminated.is_set():
        raise Terminated
    if _requested.is_set():
        raise KeyboardInterrupt


def _on_sigint(signum, frame) -> None:
    request()
    raise KeyboardInterrupt


def _on_sigterm(signum, frame) -> None:
    request(terminate=True)
    raise Terminated


@contextlib.contextmanager
def catching_sigint() -> Iterator[None]:
    """Inside it, SIGINT raises ``KeyboardInterrupt`` and SIGTERM :class:`Terminated`,
    each also recorded (see the module docstring). Outside the main thread (where
    Python allows no handler) it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    previous_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.signal(signal.SIGTERM, previous_term)
        clear()
