"""Compiled programs reused across processes: JAX's persistent compilation cache.

Details: docs/engine.md (engine/compiled.py).
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
