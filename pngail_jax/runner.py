"""Deprecated: the run lifecycle now lives in ``pngail_jax.jobs`` (``jobs.sweep.run`` and the
modules it calls). This module re-exports its old names for one minor version (until 0.3)
and will then be removed; import from ``pngail_jax`` (``run``, ``RunConfig``,
``RunResult``, ``RunError``) or from the jobs."""

import warnings

from pngail_jax.analysis.runs import sealed_part  # noqa: F401
from pngail_jax.jobs.build import BuiltRun  # noqa: F401
from pngail_jax.jobs.build import build_run as build  # noqa: F401  (its old signature)
from pngail_jax.jobs.chunks import (  # noqa: F401
    LONG_CHUNK_SECONDS,
    Progress,
    blocks_per_chunk,
    finishing_chunk,
    format_seconds,
    intact_checkpoint,
    nanmean,
    restore_checkpoint,
    stop_after_this_chunk,
)
from pngail_jax.jobs.demonstrations import (  # noqa: F401
    DEMO_CACHE,
    RANDOM_RETURN_EPISODES,
    input_files,
    load_or_make_demos,
    minari_directory,
)
from pngail_jax.jobs.demonstrations import (  # noqa: F401
    resolve_return_range as resolve_normalizer,
)
from pngail_jax.jobs.demonstrations import return_range_of as normalizer_of  # noqa: F401
from pngail_jax.jobs.errors import RunError  # noqa: F401
from pngail_jax.jobs.record import (  # noqa: F401
    SEAL,
    STALE_OUTPUTS,
    SavedRun,
    already_complete,
    check_inputs,
    drop_stale_outputs,
    load_saved,
    write_config,
)
from pngail_jax.jobs.results import (  # noqa: F401
    OUTPUT_FILES,
    RunResult,
    export_policies,
    write_outputs,
)
from pngail_jax.jobs.sweep import PROGRAM, configure_devices, run  # noqa: F401
from pngail_jax.jobs.train_seeds import train_seeds  # noqa: F401

warnings.warn(
    "pngail_jax.runner is now pngail_jax.jobs (run, RunResult, RunError: from pngail_jax); "
    "pngail_jax.runner goes in 0.3",
    DeprecationWarning,
    stacklevel=2,
)
