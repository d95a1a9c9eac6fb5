"""JAX's persistent compilation cache for the command-line programs.

A sweep's programs take 10-60 s to compile on a CPU (MJX tasks the most). With the cache on,
the second run of the same command loads them from disk instead (``docs/performance.md``
gives cold and warm compile seconds). The programs switch it on at start-up; the library
itself never does (no import-time side effects).
"""

from __future__ import annotations

import os
from pathlib import Path

CACHE_ENVIRONMENT_VARIABLE = "PNGAIL_JAX_COMPILATION_CACHE"


def default_cache_dir() -> Path:
    """``$PNGAIL_JAX_COMPILATION_CACHE``, else ``$XDG_CACHE_HOME/pngail-jax/xla`` (by default
    ``~/.cache/pngail-jax/xla``)."""
    if os.environ.get(CACHE_ENVIRONMENT_VARIABLE):
        return Path(os.environ[CACHE_ENVIRONMENT_VARIABLE])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "pngail-jax" / "xla"


def enable_compilation_cache(directory: str | Path | None = None) -> Path:
    """Turns on JAX's persistent cache in ``directory`` (default ``default_cache_dir()``) for
    every program that takes at least a second to compile. Returns the directory."""
    import jax

    directory = Path(directory) if directory is not None else default_cache_dir()
    if directory.exists() and not directory.is_dir():
        raise ValueError(f"compilation cache {directory} is a file, not a directory")
    directory.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    return directory
