"""Progress of a long command on stderr, fed by the engine's progress callbacks.

Details: docs/outputs.md (outputs/progress.py).
"""

from __future__ import annotations

import sys
import time
from typing import IO

__all__ = ["ProgressBar", "echo"]

# without a terminal (a log): a progress line at least this often while work is done
LINE_EVERY_S = 60.0


class ProgressBar:
    """A progress display that is also an engine progress callback.

    ``bar(done, total)`` reports one run's progress (the engine's ``on_progress``);
    successive runs through the same bar (a study's rounds, a bisection's steps) add
    up: a call with ``done == 0`` after a run has started begins the next run, whose
    total is added to the bar's. ``bar.advance(k)`` counts k more units of the current
    run. Use it as a context manager (or call :meth:`close`).

    Args:
      desc: what is being done ("simulating (mujoco)").
      unit: what is counted, singular ("pick", "step", "part").
      enabled: False gives a bar that shows nothing (``--no-progress``).
      total: the first run's total, if known before the first call.
      file: where to write (default: stderr); lines instead of a bar unless a terminal.
    """

    def __init__(
        self,
        desc: str,
        unit: str = "pick",
        *,
        enabled: bool = True,
        total: int | None = None,
        file: IO[str] | None = None,
    ) -> None:
        self.desc, self.unit, self.enabled = desc, unit, enabled
        self.file = file if file is not None else sys.stderr
        self._base_done = 0  # finished runs, summed
        self._base_total = 0
        self._done = 0  # the current run
        self._total = total
        self._started = False
        self._note = ""
        self._t0 = time.monotonic()
        self._tqdm = None
        self._printed: tuple[int, int | None] | None = None  # line mode: the last line
        self._next_tenth = 1
        self._last_line = self._t0
        if enabled and _is_terminal(self.file):
            from tqdm import tqdm

            self._tqdm = tqdm(total=total, unit=unit, desc=desc, file=self.file)

    # -------------------------------------------------------------- the callback
    def __call__(self, done: int, total: int | None) -> None:
        if done == 0 and self._started:  # the next run through the same bar
            self._base_done += self._done
            self._base_total += self._total or 0
        self._started = True
        self._done, self._total = int(done), total
        self._show()

    def advance(self, k: int = 1) -> None:
        """k more units of the current run done."""
        self._started = True
        self._done += k
        self._show()

    def note(self, text: str) -> None:
        """A short text shown after the counts (chunks done, rates per node)."""
        self._note = text
        if self._tqdm is not None:
            self._tqdm.set_postfix_str(text, refresh=False)

    @property
    def done(self) -> int:
        return self._base_done + self._done

    @property
    def total(self) -> int | None:
        return None if self._total is None else self._base_total + self._total

    # ------------------------------------------------------------------ display
    def _show(self) -> None:
        if not self.enabled:
            return
        done, total = self.done, self.total
        if self._tqdm is not None:
            if self._tqdm.total != total:
                self._tqdm.total = total
                self._tqdm.refresh()
            self._tqdm.update(done - self._tqdm.n)
            return
        # line mode: a line each time another tenth is done (every run's end included),
        # and -- so that a log of a long run is never silent for long -- at the first
        # work done and at least every LINE_EVERY_S seconds
        since = time.monotonic() - self._last_line
        due = done > 0 and (self._printed is None or since >= LINE_EVERY_S)
        if total:
            tenth = int(10 * done / total) if done < total else 10
            if tenth >= self._next_tenth or due:
                if tenth >= self._next_tenth:
                    self._next_tenth = tenth + 1 if done < total else 1
                self._line()
        elif due:
            self._line()

    def _line(self) -> None:
        done, total = self.done, self.total
        if self._printed == (done, total):
            return
        elapsed = time.monotonic() - self._t0
        rate = f", {done / elapsed:.3g} {self.unit}/s" if elapsed > 0 and done else ""
        count = f"{done}/{total}" if total else f"{done}"
        pct = f"{100 * done / total:3.0f}% " if total else ""
        note = f"; {self._note}" if self._note else ""
        print(
            f"{self.desc}: {pct}{count} {self.unit} [{_clock(elapsed)}{rate}]{note}",
            file=self.file,
            flush=True,
        )
        self._printed = (done, total)
        self._last_line = time.monotonic()

    def close(self) -> None:
        """End the display: the final state, shown once."""
        if not self.enabled:
            return
        if self._tqdm is not None:
            self._tqdm.close()
            self._tqdm = None
        elif self._started:
            self._line()  # nothing when the last line already said it
        self.enabled = False

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _is_terminal(file) -> bool:
    try:
        return bool(file.isatty())
    except (AttributeError, ValueError):
        return False


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    h, m = divmod(m, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


def echo(line: str, file: IO[str] | None = None) -> None:
    """Print a line (default: stdout) while a progress bar may be showing: on a terminal
    the bar is cleared, the line printed and the bar drawn again below it."""
    from tqdm import tqdm

    out = file if file is not None else sys.stdout
    tqdm.write(line, file=out)
    out.flush()
