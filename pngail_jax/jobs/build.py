"""Building a sweep: its environment, demonstrations (given, or made once and cached under
``DEMO_CACHE``), normaliser, trainer and compiled ``Grid``, and the record of its input
files."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import jax

from pngail_jax import settings as run_settings
from pngail_jax.adversarial import AdversarialTrainer
from pngail_jax.demos import (
    DemonstrationError,
    action_scale_note,
    load_demonstrations,
    released_confidence_path,
)
from pngail_jax.demos.generate import random_policy_return
from pngail_jax.demos.minari import MINARI_PREFIX
from pngail_jax.grid import Grid, make_cells, stack_cells
from pngail_jax.integrity import file_record
from pngail_jax.jobs.chunks import blocks_per_chunk
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.make_demos import PROGRAM as MAKE_PROGRAM
from pngail_jax.jobs.make_demos import MakeDemosConfig, make_claimed
from pngail_jax.outputs import claimed
from pngail_jax.run_config import RunConfig
from pngail_jax.tracking import ticking


def minari_directory(dataset_id: str) -> Path | None:
    """Where Minari keeps a local dataset (``MINARI_DATASETS_PATH``, default
    ``~/.minari/datasets``), or None when it is not there."""
    root = Path(os.environ.get("MINARI_DATASETS_PATH", "~/.minari/datasets")).expanduser()
    directory = root / dataset_id
    return directory if directory.is_dir() else None


def input_files(config: RunConfig, demos_path: str) -> dict:
    """``{role: integrity.file_record}`` of the files a run reads its demonstrations from
    (a local Minari dataset by its whole directory)."""
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


@dataclasses.dataclass
class BuiltRun:
    """A compiled grid and what its outputs need."""

    config: RunConfig
    env: object
    trainer: object
    cells: list
    grid: object
    demos_path: str
    normalizer: list[float] | None
    action_scale: float = 1.0  # what the stored actions were multiplied by
    normalizer_source: str = "none"


DEMO_CACHE = Path("runs") / "demos-cache"  # demonstrations made for runs that name none


def load_or_make_demos(config: RunConfig, saved_path: str | None = None, env=None):
    """The demonstrations and the path they came from: ``config.demos`` (a file of rows that
    is not an authors' one is split by ``env``'s sizes), else made once with
    ``jobs.make_demos`` (its defaults: 1:4 optimal to intermediate trajectories) and
    reused from ``DEMO_CACHE/<env>/``."""
    source = saved_path or config.demos
    if source is not None:
        demos = load_demonstrations(
            source,
            config.conf,
            config.action_scale,
            confidence_field=config.confidence_field,
            observation_size=None if env is None else env.observation_size,
            action_size=None if env is None else env.action_size,
        )
        return demos, source
    cached = DEMO_CACHE / config.env / "demos.npz"
    damaged = False
    if cached.exists():
        demos = _cached_demos(cached)
        if demos is not None:
            return demos, str(cached.absolute())
        damaged = True
    # Made once, under the cache's lock: a second run that finds another process making
    # them waits for it, then reuses what it made. The cache is the sweep's own: a making
    # cut short there is replaced.
    with refusals(), claimed(cached.parent, MAKE_PROGRAM, overwrite=True, wait=True) as claim:
        if cached.exists() and not damaged:  # made by the process waited for
            demos = _cached_demos(cached)
            if demos is not None:
                return demos, str(cached.absolute())
        elif not damaged:
            print(f"no demonstrations given: making them into {cached.parent}")
        make_claimed(MakeDemosConfig(env=config.env), claim)
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


def normalizer_of(demos) -> list[float] | None:
    metadata = demos.metadata
    if "random_return" in metadata and "optimal_return" in metadata:
        return [float(metadata["random_return"]), float(metadata["optimal_return"])]
    return None


RANDOM_RETURN_EPISODES = 32


def resolve_normalizer(config: RunConfig, demos, env) -> tuple[list[float] | None, str]:
    """(random, optimal) returns and where they came from: the flags, the demonstrations'
    metadata, or the flag's optimal return with a random return measured here (uniform
    random actions, ``RANDOM_RETURN_EPISODES`` episodes, a key of ``config.seed``)."""
    if config.optimal_return is None:
        normalizer = normalizer_of(demos)
        source = demos.metadata.get("normalizer_source", "the demonstrations' metadata")
        return normalizer, source if normalizer else "none"
    if config.random_return is not None:
        return [config.random_return, config.optimal_return], "--random-return, --optimal-return"
    key = jax.random.fold_in(jax.random.key(config.seed), 7)
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


def build(config: RunConfig, saved=None) -> BuiltRun:
    """Environment, demonstrations, trainer and the compiled grid of ``config`` (``saved``, a
    resumed run's ``record.SavedRun``: its demonstrations from the path it began with, its
    normaliser)."""
    cells = make_cells(
        config.methods, config.seeds, config.label_ratios, config.noise_stds, config.grid_axes
    )
    try:
        env = run_settings.make_env(config.env, config.settings, cells=len(cells))
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise RunError(f"environment: {error}") from None
    try:
        demos, demos_path = load_or_make_demos(config, saved.demos_path if saved else None, env)
    except (DemonstrationError, FileNotFoundError, ImportError) as error:
        raise RunError(f"demonstrations: {error}") from None
    try:
        trainer = AdversarialTrainer(config.adversarial_config(demos.num_rows), env, demos)
        trainer.check_methods(config.methods)
        try:
            trainer.check_label_ratios(config.label_ratios)
        except DemonstrationError:
            raise
        except ValueError as error:  # a ratio the split or the classifier cannot serve
            raise RunError(f"--label-ratio: {error}") from None
    except DemonstrationError as error:
        raise RunError(f"{demos_path}: {error}") from None
    inputs = stack_cells(
        cells, jax.random.key(config.seed), {"bsc_eps": config.task_bsc_eps},
        learner=config.learner,
    )  # fmt: skip
    eval_every = config.settings.eval_every
    num_evaluations = config.iterations // eval_every
    chunk_blocks = blocks_per_chunk(num_evaluations, max(1, config.chunk_iterations // eval_every))
    devices = jax.devices()
    if saved is not None and saved.normalizer is not None:  # as the run began
        normalizer, normalizer_source = saved.normalizer, "the run's config.json"
    else:
        normalizer, normalizer_source = resolve_normalizer(config, demos, env)
    print(
        f"{len(cells)} runs ({', '.join(config.methods)} x {config.seeds} seeds x "
        f"{config.num_settings} setting(s)) on {config.env}, {config.iterations} iterations x "
        f"{config.settings.samples_per_iteration} steps, {trainer.num_demos} demonstration "
        f"rows; {len(devices)} {devices[0].platform} device(s)\n"
        f"  {run_settings.describe(config.settings, env)}",
        flush=True,
    )
    announce_inputs(demos, trainer, normalizer, normalizer_source, config, saved)
    with ticking("compiling"):
        grid = Grid(trainer, inputs, chunk_blocks, devices)
    print(
        f"compiled in {grid.compile_seconds:.1f} s ({grid.num_cells} cells"
        f"{f', padded to {grid.num_padded}' if grid.num_padded != grid.num_cells else ''}, "
        f"{grid.iterations_per_chunk} iterations per chunk)",
        flush=True,
    )
    action_scale = float(demos.metadata.get("action_scale", 1.0))
    return BuiltRun(
        config, env, trainer, cells, grid, demos_path, normalizer, action_scale, normalizer_source
    )


def announce_inputs(demos, trainer, normalizer, normalizer_source, config, saved) -> None:
    """The notes on what the run reads: its normaliser, an applied action scale, clipped
    demonstration actions."""
    if normalizer is None:
        print(
            "note: the demonstrations carry no random/optimal returns: no normalised return "
            "(give --optimal-return, and --random-return or it is measured)"
        )
    elif config.optimal_return is not None and saved is None:
        print(
            f"normalised return: random {normalizer[0]:.1f}, optimal {normalizer[1]:.1f} "
            f"({normalizer_source})"
        )
    if action_scale_note(demos):
        print(action_scale_note(demos))
    if trainer.num_clipped_rows:
        print(
            f"note: {trainer.num_clipped_rows} of {demos.num_rows} demonstration rows have "
            "actions beyond the bounds; the discriminator sees them clipped, as the agent's "
            "(docs/methods.md)"
        )
