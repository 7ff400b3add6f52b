"""How long a run will take, said before it starts: the one estimate every interface asks.

A study's size is counted in simulations (:func:`count`: one pick-point simulated once;
a half-step check counts twice), each costs what its backend's measured rate says
(``registry.Rate``: wall seconds per pick-point on one CPU thread or one GPU, against
the pick's simulated seconds, :func:`expected_pick_s`), and this machine has so many of
those units (:func:`units_here`). :func:`estimate` gives the time; a run longer than
:data:`LONG_S` is said before it starts and the CLI asks for ``--yes``
(:func:`refuse_long`); the GUI asks the same question of the same estimate.

The rates are measured, not guessed: ``benchmarks/duration_rates.py`` (the numbers,
their machines and dates in each entry's ``Rate`` and in benchmarks/RESULTS.md). An
estimate is a guide within a factor of about two: parts, grippers and contact settings
cost more or less per physics step than the block and door opener measured.
"""

from __future__ import annotations

import dataclasses
import math
import os

from mjx_pick.core.config import ConfigError
from mjx_pick.core.physics import SolverParams
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import registry

__all__ = ["Estimate", "LONG_S", "count", "estimate", "expected_pick_s", "refuse_long"]

# "a few minutes": a run estimated longer is said first and needs confirming (--yes)
LONG_S = 300.0

# The close until the force is reached, simulated seconds: the mean t_reached_s of the
# measured runs (benchmarks/duration_rates.py, 2026-11-28: 0.46 s on the block, 0.53 s on
# the door opener, robotiq-2f85 at the default procedure); a pick whose force is never
# reached runs the whole close timeout, a minority in a useful run.
TYPICAL_CLOSE_S = 0.5

# Evaluate's extra passes, each a simulation of every pick-point again: the minimum
# force's bisection halves the gripper's force range down to 0.5 N (robust.ForceSearch:
# about 9 halvings of a 20-235 N range); the step check runs at half the time step
# (twice the physics steps).
MIN_FORCE_PASSES = 9
STEP_CHECK_PASSES = 2


def expected_pick_s(grasp: GraspConfig | None = None) -> float:
    """Simulated seconds a pick-point typically runs: every phase at its planned length,
    the close at its typical one (:data:`TYPICAL_CLOSE_S`, at most its timeout)."""
    g = grasp or GraspConfig()
    close = min(g.close_timeout_s, TYPICAL_CLOSE_S)
    return close + g.dwell_s + g.lift_s + g.hold_s  # t_reached_s counts the settle too


def _nvidia_gpus() -> int:
    from mjx_pick.engine.devices import nvidia_gpu_count

    return nvidia_gpu_count()


def units_here(entry: registry.BackendEntry) -> tuple[int, str]:
    """(how many, what) of the units the backend's rate is per on this machine: CPU
    threads (the C engine runs one simulation per thread, as many as ``os.cpu_count``),
    NVIDIA GPUs (at least one: a backend that needs one is refused elsewhere where
    there is none), or one JAX device."""
    if entry.device is registry.Device.CPU:
        n = os.cpu_count() or 1
        return n, f"CPU thread{'s' if n > 1 else ''}"
    if entry.device is registry.Device.NVIDIA_GPU:
        n = max(_nvidia_gpus(), 1)
        return n, f"GPU{'s' if n > 1 else ''}"
    return 1, "JAX device"


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A run's expected duration on this machine: its simulations, the seconds they
    take at per_s simulations a second, on `backend` with `where` (its units), and the
    rate's source (a measurement)."""

    simulations: int
    seconds: float
    per_s: float
    backend: str
    where: str
    source: str

    @property
    def long(self) -> bool:
        """Longer than :data:`LONG_S`: said first, and confirmed before it starts."""
        return self.seconds > LONG_S

    def text(self) -> str:
        """'about 3 h 20 min (1,000,000 simulations at ~83 a second: mujoco on 2 CPU
        threads)'."""
        return (
            f"about {clock_words(self.seconds)} ({self.simulations:,} simulations at "
            f"~{self.per_s:,.3g} a second: {self.backend} on {self.where})"
        )


def clock_words(seconds: float) -> str:
    """A duration as a person says it: '40 s', '12 min', '3 h 20 min', '12 days'."""
    if seconds < 90:
        return f"{max(seconds, 1):.0f} s"
    minutes = seconds / 60
    if minutes < 90:
        return f"{minutes:.0f} min"
    hours = minutes / 60
    if hours < 48:
        whole = int(hours)
        rest = int(round(minutes - 60 * whole))
        return f"{whole} h" + (f" {rest} min" if rest else "")
    return f"{hours / 24:.0f} days"


def estimate(
    simulations: int,
    grasp: GraspConfig | None = None,
    solver: SolverParams | None = None,
    backend: str = registry.AUTO,
    *,
    ray: str | None = None,
) -> Estimate | None:
    """How long `simulations` pick-point simulations of this procedure take on this
    machine with `backend` ('auto' resolved here); None where it cannot be said: on a
    Ray cluster (its machines are not this one), or for a backend that states no rate.

    The cost of one pick on one unit is the backend's measured rate at the pick's
    expected simulated seconds, scaled by the time step (the physics steps it takes)."""
    if ray is not None or simulations <= 0:
        return None
    entry = registry.entry(backend)
    rate = entry.rate
    if rate is None:
        return None
    solver = solver or SolverParams()
    steps = SolverParams().timestep_s / solver.timestep_s  # relative to the measured step
    units, what = units_here(entry)
    per_sim_s = rate.per_sim_s
    if rate.gpu_per_sim_s is not None and _nvidia_gpus() > 0:
        per_sim_s, what = rate.gpu_per_sim_s, "GPU (JAX)"
    simulated = (grasp or GraspConfig()).duration_s if rate.full_length else expected_pick_s(grasp)
    per_s = units / (per_sim_s * simulated * steps)
    return Estimate(
        int(simulations), simulations / per_s, per_s, entry.name, f"{units} {what}", rate.source
    )


def refuse_long(est: Estimate | None, what: str, yes: bool) -> str | None:
    """A run estimated longer than :data:`LONG_S` is refused (ConfigError saying how
    long and what to pass) unless yes; then the line to show before it starts. None
    for a short run or one that cannot be estimated."""
    if est is None or not est.long:
        return None
    if not yes:
        raise ConfigError(
            f"{what} would take {est.text()} on this machine; pass --yes to start it, or "
            "make it smaller"
        )
    return f"{what}: {est.text()}; started (--yes)"


def count(study: str, **sizes) -> int:
    """The simulations a study runs at most, from its sizes (the CLI's and the GUI's
    values): see each ``_count_<study>`` for the sizes it takes."""
    counters = {
        "evaluate": _count_evaluate,
        "sweep": _count_product,
        "compare": _count_product,
        "design": _count_design,
        "robust": _count_robust,
        "calibrate": _count_calibrate,
    }
    if study not in counters:
        raise ValueError(f"no count for study {study!r}: choose one of {', '.join(counters)}")
    return int(counters[study](**sizes))


def _count_evaluate(
    n: int | None = None,
    picks=None,
    until: int | None = None,
    max_n: int | None = None,
    min_force: bool = False,
    stability_um: float = 0.0,
    step_check: bool = False,
) -> int:
    """n pick-points (default 1000), a picks file's rows or a GraspBatch's length, or
    Optimization mode's most (max_n, else 10 x until); each extra check a pass more."""
    if until is not None:
        base = max_n or 10 * until
    elif picks is not None:
        base = _rows(picks)
    else:
        base = n if n is not None else 1000
    passes = 1 + (stability_um > 0) + STEP_CHECK_PASSES * bool(step_check)
    passes += MIN_FORCE_PASSES * bool(min_force)
    return base * passes


def _rows(picks) -> int:
    """The rows of a picks CSV (lines after the header; counted, not parsed) or a
    GraspBatch's length."""
    if not isinstance(picks, str | os.PathLike):
        return len(picks)
    try:
        with open(picks, "rb") as fh:
            lines = sum(1 for line in fh if line.strip())
    except OSError:
        return 0  # the reader refuses it, naming why
    return max(lines - 1, 0)


def _count_product(variants: int, n: int) -> int:
    """A sweep's variants (or a comparison's grippers) x n pick-points each."""
    return variants * n


def _count_design(variants: int, rounds: int, n: int, final_n: int | None = None) -> int:
    """Round r compares the surviving third of the last round's variants on n x 2^r
    pick-points (``comparison._rounds``); the final compares the best and the base
    gripper on final_n (default 4 n)."""
    total, pool = 0, variants
    for r in range(rounds):
        total += pool * n * 2**r
        pool = max(1, math.ceil(pool / 3)) if r < rounds - 1 else 1
    return total + 2 * (final_n or 4 * n)


def _count_robust(top_k: int, m: int, n: int | None = None) -> int:
    """top_k pick-points x m perturbed draws, after n drawn and simulated first (None:
    ranked from an earlier run's results)."""
    return top_k * m + (n or 0)


def _count_calibrate(steps: int, vectors: int, rows: int) -> int:
    """An estimator's steps x the parameter vectors each step simulates x the rows
    each vector simulates (the identifiability check after the fit comes on top)."""
    return max(steps, 1) * vectors * rows
