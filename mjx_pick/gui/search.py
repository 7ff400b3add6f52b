"""A search for feasible pick-points run by the page: how far it is, and a stop.

Drawing pick-points (tab 3's map, the count a run's progress bar is cut by) can check up
to ``picks.max_candidates`` candidate poses when few are feasible (a high minimum
coverage, a part that barely fits): the page shows how far the search is and can stop it.
"""

from __future__ import annotations

import threading

from mjx_pick.core.pickpoints import rejected_text


class SearchStopped(Exception):
    """The user stopped a search (raised inside it, from its progress callback)."""


class Search:
    """The progress callback of one ``generate_normal`` run in a worker thread; the page
    reads it while the search runs and may ask it to stop."""

    def __init__(self, wanted: int, most: int):
        """wanted: the feasible pick-points asked for; most: the candidates drawn at most
        (``picks.max_candidates``)."""
        self.wanted, self.most = int(wanted), int(most)
        self.drawn = self.found = 0
        self.rejected: dict[str, int] = {}
        self._stop = threading.Event()

    def __call__(self, drawn: int, found: int, rejected: dict) -> None:
        """generate_normal's progress(drawn, found, rejected): noted; raises
        SearchStopped once a stop was asked for."""
        self.drawn, self.found, self.rejected = int(drawn), int(found), dict(rejected)
        if self._stop.is_set():
            raise SearchStopped

    def stop(self) -> None:
        """Ask the search to stop after the block it checks now."""
        self._stop.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    @property
    def fraction(self) -> float:
        """How far it is, 0-1: the larger of the feasible share found and the candidate
        share drawn (it ends at whichever comes first)."""
        return min(1.0, max(self.found / max(self.wanted, 1), self.drawn / max(self.most, 1)))

    def text(self) -> str:
        """What the page says while it runs."""
        return (
            f"checking candidate poses: {self.drawn:,} of at most {self.most:,} checked, "
            f"{self.found:,} of {self.wanted:,} feasible so far (rejected: "
            f"{rejected_text(self.rejected)})"
        )

    def ended_text(self) -> str:
        """What the page says once a search ended without its pick-points (the caller
        says why): how far it got -- never its last "so far" line, as if it still ran."""
        return (
            f"the search ended after {self._checked()} candidate poses: {self.found:,} of "
            f"{self.wanted:,} feasible (rejected: {rejected_text(self.rejected)})"
        )

    def _checked(self) -> str:
        """The candidates checked, against the most it draws (whole blocks: the last
        may pass it)."""
        if self.drawn >= self.most:
            return f"{self.drawn:,} (all it draws, at most {self.most:,} rounded up to a block)"
        return f"{self.drawn:,} of at most {self.most:,}"

    def stopped_text(self) -> str:
        """What the page says after a stop."""
        return (
            f"stopped after {self.drawn:,} of at most {self.most:,} candidate poses: "
            f"{self.found:,} feasible (rejected: {rejected_text(self.rejected)})"
        )
