"""Compiled programs reused across processes: JAX's persistent compilation cache.

Every new process compiles its device programs again (the MJX/Warp rollouts, the C
engine's per-tick controller), which on a short run costs more than the simulation.
JAX can keep compiled executables on disk; :func:`use_persistent_cache` points it at the
``jax/`` subfolder of mjx-pick's cache folder (``mjx_pick.core.cache``). The engine calls
it when it builds a backend that runs JAX programs -- the point where a command or a
study starts simulating -- never at import time (nor in a process that never uses JAX).

* Programs that compiled in less than :data:`MIN_COMPILE_S` are not stored: reading an
  entry costs about as much as compiling the smallest programs (single operations run
  eagerly), and they would fill the folder. The C engine's per-tick controller, the
  feasibility check and the results' finalisation are small programs, yet together they
  can cost a short run more than its simulation: they are kept.
* Bypassed with the rest of the cache (``MJX_PICK_CACHE=0``, the CLI's ``--no-cache``).
* A folder set already -- ``JAX_COMPILATION_CACHE_DIR`` or the user's own
  ``jax.config.update`` -- is left as it is.
* Its size is kept under three quarters of ``MJX_PICK_CACHE_MAX_MB`` by JAX's own
  least-recently-used eviction (which needs the ``filelock`` package).
* JAX fixes the folder at the first compile that uses it: a later change of
  ``MJX_PICK_CACHE_DIR`` in the same process moves only the object results.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from mjx_pick.core import cache

MIN_COMPILE_S = 0.1  # seconds: programs that compile faster are not stored


def use_persistent_cache() -> Path | None:
    """Turn on JAX's persistent compilation cache in the cache folder's ``jax/``.

    Returns:
      the folder JAX keeps compiled programs in (this one, or one the user set), or
      None when the cache is bypassed or its folder cannot be written (one warning).
    """
    import jax

    current = jax.config.jax_compilation_cache_dir
    if current:
        return Path(current)
    if not cache.enabled():
        return None
    folder = cache.root() / "jax"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".probe."):
            pass
    except OSError as err:  # the object results of this folder warn of it the same way
        cache.warn_once(
            folder.parent,
            "unwritable",
            f"mjx-pick cache {folder}: cannot be written ({err.strerror or err}); compiled "
            "programs are not kept",
        )
        return None
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_S)
    # JAX's eviction locks with filelock, a declared dependency
    share = int(cache.limit_bytes() * (1.0 - cache.OBJECT_SHARE))
    jax.config.update("jax_compilation_cache_max_size", max(share, 1))
    jax.config.update("jax_compilation_cache_dir", str(folder))
    return folder
