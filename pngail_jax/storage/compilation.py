"""JAX's persistent compilation cache for the command-line programs.

A sweep's programs take 10-60 s to compile on a CPU (MJX tasks the most). With the cache on,
the second run of the same command loads them from disk instead (``docs/performance.md``
gives cold and warm compile seconds). The programs switch it on at start-up; the library
itself never does (no import-time side effects).
"""

from __future__ import annotations

import functools
import os
import time
import warnings
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
    cache_programs_with_callbacks(directory / CALLBACK_PROGRAMS)
    return directory


# Where ``cache_programs_with_callbacks`` keeps its programs, inside the cache's folder.
CALLBACK_PROGRAMS = "with-host-callbacks"
_callback_cache: dict[str, Path] = {}


def cache_programs_with_callbacks(directory: str | Path) -> bool:
    """Keeps the compiled programs that call back to the host (MuJoCo's C engine, through
    ``jax.pure_callback``) in ``directory`` too, which JAX's persistent cache never writes.

    Why that is safe in this JAX: a CPU program reaches its callbacks through an FFI call
    that names a callback by its index in the lowered module's list, not by an address baked
    into the program; the list is handed to the executable when it is loaded. So an entry
    is keyed by JAX's own cache key of the module (its text with the callback indices, the
    compile options, the backend, the JAX and jaxlib versions) and loaded with the callbacks
    this process lowered for the same module, in the same order: the program is the one XLA
    would compile, and it calls this process's Python functions.

    Returns whether it is on: it steps aside (JAX's own compile as before) in a JAX whose
    internals differ (checked: the private function it wraps and its arguments), and the
    wrapper itself for a multi-process run, a backend other than the CPU, a program without
    callbacks, the cache turned off (``jax_enable_compilation_cache``) and any failure to
    read or write an entry."""
    import inspect

    try:
        from jax._src import compiler
    except ImportError:
        return False
    original = getattr(compiler, "compile_or_get_cached", None)
    expected = ["backend", "computation", "devices", "compile_options", "host_callbacks",
                "executable_devices", "pgle_profiler"]  # fmt: skip
    if original is None or getattr(original, "_pngail_jax_wrapped", False):
        _callback_cache["directory"] = Path(directory)
        return original is not None
    if list(inspect.signature(original).parameters) != expected:
        return False
    _callback_cache["directory"] = Path(directory)
    wrapped = functools.partial(_compile_or_read, original)
    wrapped._pngail_jax_wrapped = True
    compiler.compile_or_get_cached = wrapped
    return True


def _compile_or_read(original, backend, computation, devices, compile_options, host_callbacks,
                     executable_devices, pgle_profiler=None):  # fmt: skip
    """JAX's ``compile_or_get_cached``, and for a program with host callbacks, the entry of
    ``cache_programs_with_callbacks`` (read, or compiled and written)."""
    import jax
    from jax._src import cache_key, compiler

    arguments = (backend, computation, devices, compile_options, host_callbacks,
                 executable_devices, pgle_profiler)  # fmt: skip
    directory = _callback_cache.get("directory")
    enabled = jax.config.jax_enable_compilation_cache and directory is not None
    # CPU only: its callbacks by index are what this was checked against (a TPU's lower
    # another way); one process only, as JAX's cache writes from one.
    if not (host_callbacks and enabled and backend.platform == "cpu"):
        return original(*arguments)
    if jax.process_count() > 1:
        return original(*arguments)
    try:
        path = directory / cache_key.get(computation, devices, compile_options, backend)
    except Exception:  # a module JAX cannot key: compiled as JAX would
        return original(*arguments)
    start = time.monotonic()
    if path.is_file():
        try:
            executable = backend.deserialize_executable(
                path.read_bytes(), executable_devices, compile_options,
                host_callbacks=host_callbacks,
            )  # fmt: skip
        except Exception as error:
            warnings.warn(
                f"compilation cache: {path} not read ({error}); compiling again", stacklevel=2
            )
        else:
            jax.monitoring.record_event("/jax/compilation_cache/cache_hits")
            jax.monitoring.record_event_duration_secs(
                "/jax/compilation_cache/cache_retrieval_time_sec", time.monotonic() - start
            )
            return executable
    executable = compiler.backend_compile_and_load(
        backend, computation, executable_devices, compile_options, host_callbacks
    )
    try:
        directory.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.partial")
        partial.write_bytes(backend.serialize_executable(executable))
        partial.replace(path)  # whole or absent: a reader never sees half an entry
    except Exception as error:
        warnings.warn(f"compilation cache: {path} not written ({error})", stacklevel=2)
    return executable
