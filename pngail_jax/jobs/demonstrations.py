"""A sweep's demonstrations, the step of its lifecycle before the build: read from the file
the config names (or a resumed run's own path), or made once with ``jobs.make_demos`` and
cached (``demos_cache``); their return range, the random and optimal returns (the flags, their
metadata, or a random return measured here); and the record of the input files a resume checks.

    demonstrations = prepare(config, env)      # a RunDemonstrations
    built = build.build(config, env, cells, demonstrations)
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import jax

from pngail_jax.config.demonstrations import DemonstrationsConfig
from pngail_jax.config.run_config import RunConfig
from pngail_jax.demos import (
    DemonstrationError,
    Demonstrations,
    load_demonstrations,
    released_confidence_path,
)
from pngail_jax.demos.generate import random_policy_return
from pngail_jax.demos.minari import MINARI_PREFIX
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.make_demos import PROGRAM as MAKE_PROGRAM
from pngail_jax.jobs.make_demos import MakeDemosConfig, make_claimed
from pngail_jax.storage.integrity import file_record
from pngail_jax.storage.outputs import claimed


@dataclasses.dataclass(frozen=True)
class RunDemonstrations:
    """A run's demonstrations, the path they came from, and their return range
    ((random, optimal), None without one) with where that came from."""

    demos: Demonstrations
    path: str
    return_range: list[float] | None
    return_range_source: str

    @property
    def action_scale(self) -> float:
        """What the stored actions were multiplied by."""
        return float(self.demos.metadata.get("action_scale", 1.0))


def prepare(config: RunConfig, env, saved=None) -> RunDemonstrations:
    """The demonstrations of ``config`` for ``env`` (``saved``, a resumed run's
    ``record.SavedRun``: its demonstrations from the path it began with, its return range).
    Raises ``RunError`` with one line."""
    try:
        demos, path = load_or_make_demos(config, saved.demos_path if saved else None, env)
    except (DemonstrationError, FileNotFoundError, ImportError) as error:
        raise RunError(f"demonstrations: {error}") from None
    if saved is not None and saved.return_range is not None:  # as the run began
        return_range, source = saved.return_range, "the run's config.json"
    else:
        return_range, source = resolve_return_range(config, demos, env)
    return RunDemonstrations(demos, path, return_range, source)


def minari_directory(dataset_id: str) -> Path | None:
    """Where Minari keeps a local dataset (``MINARI_DATASETS_PATH``, default
    ``~/.minari/datasets``), or None when it is not there."""
    root = Path(os.environ.get("MINARI_DATASETS_PATH", "~/.minari/datasets")).expanduser()
    directory = root / dataset_id
    return directory if directory.is_dir() else None


def input_files(config: DemonstrationsConfig, demos_path: str) -> dict:
    """``{role: integrity.file_record}`` of the files a run reads its demonstrations from
    (a local Minari dataset by its whole directory); ``config``: the run's demonstrations
    part."""
    if demos_path.startswith(MINARI_PREFIX):
        files = {"confidence file": config.conf} if config.conf else {}
        dataset = minari_directory(demos_path.removeprefix(MINARI_PREFIX))
        if dataset is not None:  # its content, not only its id: a rebuilt dataset differs
            files["Minari dataset"] = dataset
    else:
        files = {"demonstrations": demos_path}
        if config.conf or demos_path.endswith("_mixture.npy"):
            files["confidence file"] = config.conf or released_confidence_path(demos_path)
    return {role: file_record(path) for role, path in files.items()}


# Demonstrations made for runs that name none: $PNGAIL_JAX_DEMOS_CACHE, else this folder of
# the working directory (``demos_cache``).
DEMO_CACHE = Path("runs") / "demos-cache"
DEMO_CACHE_VARIABLE = "PNGAIL_JAX_DEMOS_CACHE"


def demos_cache() -> Path:
    """Where runs that name no demonstrations keep the ones made for them, one folder per
    task: ``$PNGAIL_JAX_DEMOS_CACHE`` when set (one cache for every working directory),
    else ``DEMO_CACHE`` (``runs/demos-cache`` of the working directory)."""
    return Path(os.environ.get(DEMO_CACHE_VARIABLE) or DEMO_CACHE).expanduser()


def load_or_make_demos(config, saved_path: str | None = None, env=None):
    """The demonstrations and the path they came from: ``config.demonstrations.demos`` (a
    file of rows that is not an authors' one is split by ``env``'s sizes), else made once
    with ``jobs.make_demos`` (its defaults: 1:4 optimal to intermediate trajectories) and
    reused from ``demos_cache()/<config.env>/``. ``config``: a job's config with its task
    (``env``) and its demonstrations part (``RunConfig``, ``OfflineRunConfig``)."""
    files = config.demonstrations
    source = saved_path or files.demos
    if source is not None:
        demos = load_demonstrations(
            source,
            files.conf,
            files.action_scale,
            confidence_field=files.confidence_field,
            observation_size=None if env is None else env.observation_size,
            action_size=None if env is None else env.action_size,
        )
        return demos, source
    cached = demos_cache() / config.env / "demos.npz"
    damaged = False
    if cached.exists():
        demos = _cached_demos(cached)
        if demos is not None:
            return demos, str(cached.absolute())
        damaged = True
    # Made once, under the cache's lock: a second run that finds another process making
    # them waits for it, then reuses what it made. The cache is the sweep's own: a making
    # cut short there continues from its last block (``continue_cut``).
    with refusals(), claimed(cached.parent, MAKE_PROGRAM, overwrite=True, wait=True) as claim:
        if cached.exists() and not damaged:  # made by the process waited for
            demos = _cached_demos(cached)
            if demos is not None:
                return demos, str(cached.absolute())
        elif not damaged:
            print(f"no demonstrations given: making them into {cached.parent}")
        make_claimed(MakeDemosConfig(env=config.env), claim, continue_cut=True)
    return load_demonstrations(cached), str(cached.absolute())


def _cached_demos(cached: Path):
    """The cached demonstrations, or None (saying so) when the file is damaged."""
    try:
        demos = load_demonstrations(cached)
    except DemonstrationError as error:
        print(f"the cached demonstrations are damaged: {error}; making them again")
        return None
    print(f"reusing demonstrations {cached}", flush=True)
    return demos


def return_range_of(demos) -> list[float] | None:
    metadata = demos.metadata
    if "random_return" in metadata and "optimal_return" in metadata:
        return [float(metadata["random_return"]), float(metadata["optimal_return"])]
    return None


RANDOM_RETURN_EPISODES = 32


def resolve_return_range(config, demos, env) -> tuple[list[float] | None, str]:
    """(random, optimal) returns and where they came from: the flags, the demonstrations'
    metadata, or the flag's optimal return with a random return measured here (uniform
    random actions, ``RANDOM_RETURN_EPISODES`` episodes, a key of ``config.seed``).
    ``config``: a job's config with its base seed and its demonstrations part."""
    seed, config = config.seed, config.demonstrations
    if config.optimal_return is None:
        return_range = return_range_of(demos)
        source = demos.metadata.get("normalizer_source", "the demonstrations' metadata")
        return return_range, source if return_range else "none"
    if config.random_return is not None:
        return [config.random_return, config.optimal_return], "--random-return, --optimal-return"
    key = jax.random.fold_in(jax.random.key(seed), 7)
    random_return = random_policy_return(env, key, RANDOM_RETURN_EPISODES)
    if not config.optimal_return > random_return:
        raise RunError(
            f"--optimal-return {config.optimal_return:g} is not above the random policy's "
            f"return, {random_return:.1f} (measured): give the best return the task allows"
        )
    return [random_return, config.optimal_return], (
        f"--optimal-return; random return measured ({RANDOM_RETURN_EPISODES} episodes of "
        "uniform random actions)"
    )
