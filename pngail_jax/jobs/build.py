"""Building a sweep, as named steps (``build_run``): its cells, its environment, its
demonstrations (``jobs.demonstrations.prepare``: read or made, and their return range), then
``build``, which receives them: the trainer and the compiled ``Grid``."""

from __future__ import annotations

import dataclasses

import jax

from pngail_jax import envs
from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.trainer import AdversarialTrainer
from pngail_jax.analysis.tracking import ticking
from pngail_jax.config import settings as env_settings
from pngail_jax.config.run_config import RunConfig
from pngail_jax.demos import DemonstrationError, action_scale_note
from pngail_jax.grid import Cell, Grid, make_cells, stack_cells
from pngail_jax.jobs import trainer_configs
from pngail_jax.jobs.chunks import blocks_per_chunk
from pngail_jax.jobs.demonstrations import RunDemonstrations, prepare
from pngail_jax.jobs.errors import RunError


@dataclasses.dataclass
class BuiltRun:
    """A compiled grid and what its outputs need."""

    config: RunConfig
    env: envs.Env
    trainer: AdversarialTrainer
    cells: list[Cell]
    grid: Grid
    demonstrations: RunDemonstrations

    @property
    def demos_path(self) -> str:
        return self.demonstrations.path

    @property
    def return_range(self) -> list[float] | None:
        return self.demonstrations.return_range

    @property
    def return_range_source(self) -> str:
        return self.demonstrations.return_range_source

    @property
    def action_scale(self) -> float:
        return self.demonstrations.action_scale


def build_run(config: RunConfig, saved=None) -> BuiltRun:
    """Every step of a sweep's build (``saved``: a resumed run's ``record.SavedRun``, whose
    demonstrations and return range are those it began with)."""
    cells = run_cells(config)
    env = make_run_env(config, cells)
    demonstrations = prepare(config, env, saved)
    return build(config, env, cells, demonstrations, resumed=saved is not None)


def run_cells(config: RunConfig) -> list[Cell]:
    """The grid's cells: every setting x method x seed of ``config``."""
    return make_cells(
        config.methods, config.seeds, config.label_ratios, config.noise_stds, config.grid_axes
    )


def make_run_env(config: RunConfig, cells: list[Cell]) -> envs.Env:
    """The task's environment, sized for the grid (a batched engine's width)."""
    try:
        return env_settings.make_env(config.env, config.settings, cells=len(cells))
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise RunError(f"environment: {error}") from None


def build(
    config: RunConfig,
    env: envs.Env,
    cells: list[Cell],
    demonstrations: RunDemonstrations,
    resumed: bool = False,
) -> BuiltRun:
    """The trainer of ``demonstrations`` in ``env`` (the methods and label ratios checked
    against it) and the compiled grid of ``cells``."""
    demos, demos_path = demonstrations.demos, demonstrations.path
    try:
        trainer = AdversarialTrainer(
            trainer_configs.adversarial_config(config, demos.num_rows), env, demos
        )
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
        family=ADVERSARIAL, learner=config.learner.name,
    )  # fmt: skip
    eval_every = config.settings.eval_every
    num_evaluations = config.iterations // eval_every
    chunk_blocks = blocks_per_chunk(num_evaluations, max(1, config.chunk_iterations // eval_every))
    devices = jax.devices()
    print(
        f"{len(cells)} runs ({', '.join(config.methods)} x {config.seeds} seeds x "
        f"{config.num_settings} setting(s)) on {config.env}, {config.iterations} iterations x "
        f"{config.settings.samples_per_iteration} steps, {trainer.num_demos} demonstration "
        f"rows; {len(devices)} {devices[0].platform} device(s)\n"
        f"  {env_settings.describe(config.settings, env)}",
        flush=True,
    )
    announce_inputs(demonstrations, trainer, config, resumed)
    with ticking("compiling"):
        grid = Grid(trainer, inputs, chunk_blocks, devices)
    print(
        f"compiled in {grid.compile_seconds:.1f} s ({grid.num_cells} cells"
        f"{f', padded to {grid.num_padded}' if grid.num_padded != grid.num_cells else ''}, "
        f"{grid.iterations_per_chunk} iterations per chunk)",
        flush=True,
    )
    return BuiltRun(config, env, trainer, cells, grid, demonstrations)


def announce_inputs(
    demonstrations: RunDemonstrations, trainer, config: RunConfig, resumed: bool
) -> None:
    """The notes on what the run reads: its return range, an applied action scale, clipped
    demonstration actions."""
    demos, return_range = demonstrations.demos, demonstrations.return_range
    if return_range is None:
        print(
            "note: the demonstrations carry no random/optimal returns: no normalised return "
            "(give --optimal-return, and --random-return or it is measured)"
        )
    elif config.optimal_return is not None and not resumed:
        print(
            f"normalised return: random {return_range[0]:.1f}, optimal {return_range[1]:.1f} "
            f"({demonstrations.return_range_source})"
        )
    if action_scale_note(demos):
        print(action_scale_note(demos))
    if trainer.num_clipped_rows:
        print(
            f"note: {trainer.num_clipped_rows} of {demos.num_rows} demonstration rows have "
            "actions beyond the bounds; the discriminator sees them clipped, as the agent's "
            "(docs/methods.md)"
        )
