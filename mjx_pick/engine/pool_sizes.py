"""Sizes of a refilled pool of simulation slots (both GPU pools use them)."""

from __future__ import annotations

# halvings of a pool in a run's tail: as picks run out, a half-empty pool moves its live
# slots into a pool half its size, so the tail does not pay for idle slots
DEFAULT_SHRINK_LEVELS = 3
# the tail never shrinks a pool below this many slots per device: a small pool's GPU
# step is bound by kernel launches more than by its slot count, so a halving saves
# little, while every pool size is one more model and data to build
SHRINK_MIN_SLOTS = 4096


def shrink_sizes(slots: int, levels: int, min_slots: int = 1) -> tuple[int, ...]:
    """Pool sizes of a run's tail: slots, halved up to `levels` times while the halves
    stay whole numbers of at least min_slots (slots per device)."""
    sizes = [int(slots)]
    while len(sizes) <= levels and sizes[-1] % 2 == 0 and sizes[-1] // 2 >= max(min_slots, 1):
        sizes.append(sizes[-1] // 2)
    return tuple(sizes)
