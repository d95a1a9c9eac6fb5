"""``run_offline(OfflineRunConfig, out)``: the offline family (BC on the expert rows, BC on
every row, DWBC, ISW-BC) on a task's demonstrations, every method x seed in one compiled
``Grid`` of ``OfflineTrainer``, with the online sweep's evaluation and outputs: config.json,
metrics.csv, summary.json / summary.md (IQM and intervals, each method's probability of
beating BC on every row) and curves.png, so the rows join the sweep's tables.

A program of its own rather than sweep methods: the offline trainer has no rollout, learner
or discriminator schedule of the adversarial grid, so its config (gradient steps, batch size)
shares almost nothing with ``RunConfig``; what it shares (demonstrations, normaliser, split,
evaluation, summary) it takes from the same functions.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import numpy as np

from pngail_jax import report
from pngail_jax import settings as run_settings
from pngail_jax.demos import DemonstrationError
from pngail_jax.grid import Grid, make_cells, nonfinite_cells
from pngail_jax.integrity import write_json
from pngail_jax.jobs.build import input_files, load_or_make_demos, resolve_normalizer
from pngail_jax.jobs.chunks import blocks_per_chunk, format_seconds, run_chunks, start
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.offline import (
    OFFLINE_METHOD_NAMES,
    OfflineConfig,
    OfflineTrainer,
    required_components,
    stack_offline_cells,
)
from pngail_jax.outputs import claimed
from pngail_jax.run_config import RunConfig, provenance
from pngail_jax.tracking import ticking

PROGRAM = "offline"


@dataclasses.dataclass(frozen=True)
class OfflineRunConfig:
    """One offline grid: methods x seeds on one task's demonstrations."""

    env: str = "Pendulum-v1"
    demos: str | None = None  # None: made once and cached, as the sweep's
    conf: str | None = None
    action_scale: float | None = None
    methods: tuple[str, ...] = OFFLINE_METHOD_NAMES
    seeds: int = 5
    seed: int = 0
    label_ratio: float = 0.2
    noise_std: float = 0.0
    gradient_steps: int = 50_000
    steps_per_iteration: int = 1_000
    eval_every: int = 5  # iterations (of steps_per_iteration) per evaluation
    chunk_iterations: int = 10
    batch_size: int = 256
    num_eval_episodes: int | None = None  # None: the task's (RunSettings)
    hidden_sizes: tuple[int, ...] = (100, 100)

    def __post_init__(self):
        if not self.methods or len(set(self.methods)) != len(self.methods):
            raise ValueError(f"methods must be distinct and not empty, got {self.methods!r}")
        required_components(self.methods)  # unknown names: one line naming them
        for name in ("seeds", "gradient_steps", "steps_per_iteration", "eval_every",
                     "chunk_iterations", "batch_size"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        block = self.steps_per_iteration * self.eval_every
        if self.gradient_steps % block:
            raise ValueError(
                f"gradient_steps ({self.gradient_steps}) must be a multiple of "
                f"steps_per_iteration x eval_every = {block} (one evaluation each)"
            )
        if not 0 < self.label_ratio < 1:
            raise ValueError(f"label_ratio must lie in (0, 1), got {self.label_ratio!r}")

    @property
    def run_config(self) -> RunConfig:
        """The sweep's config of the same task and files: what the demonstrations, the
        normaliser and the environment are read with."""
        return RunConfig(
            env=self.env, demos=self.demos, conf=self.conf, action_scale=self.action_scale,
            methods=("gail",), seeds=self.seeds, seed=self.seed,
            label_ratios=(self.label_ratio,), noise_stds=(self.noise_std,),
        )  # fmt: skip

    def trainer_config(self, num_rows: int) -> OfflineConfig:
        run_config = self.run_config
        return OfflineConfig(
            num_iterations=self.gradient_steps // self.steps_per_iteration,
            steps_per_iteration=self.steps_per_iteration,
            eval_every=self.eval_every,
            num_eval_episodes=self.num_eval_episodes or run_config.settings.num_eval_episodes,
            batch_size=self.batch_size,
            hidden_sizes=self.hidden_sizes,
            num_demos=run_config.task_num_demos(num_rows),
            classifier=run_config.adversarial_config(num_rows).classifier,
            components=required_components(self.methods),
        )


def run_offline(config: OfflineRunConfig, out: str | Path, overwrite: bool = False) -> dict:
    """Trains the grid and writes its outputs into ``out``; returns the summary. Raises
    ``RunError`` with one line for a refused output directory or unusable inputs."""
    out = Path(out)
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite) as claim:
        run_config = config.run_config
        try:
            env = run_settings.make_env(config.env, run_config.settings)
            demos, demos_path = load_or_make_demos(run_config, None, env)
        except (DemonstrationError, FileNotFoundError, ImportError, ValueError) as error:
            raise RunError(f"demonstrations: {error}") from None
        if demos.confidence is None:
            raise RunError(f"{demos_path}: no confidences, which every offline method reads")
        trainer = OfflineTrainer(config.trainer_config(demos.num_rows), env, demos)
        normalizer, normalizer_source = resolve_normalizer(run_config, demos, env)
        claim.prepare()
        cells = make_cells(config.methods, config.seeds, (config.label_ratio,),
                           (config.noise_std,))  # fmt: skip
        inputs = stack_offline_cells(cells, jax.random.key(config.seed))
        trainer_config = trainer.config
        target = max(1, config.chunk_iterations // trainer_config.eval_every)
        chunk_blocks = blocks_per_chunk(trainer_config.num_evaluations, target)
        print(
            f"{len(cells)} offline runs ({', '.join(config.methods)} x {config.seeds} seeds) on "
            f"{config.env}, {config.gradient_steps:,} gradient steps of {config.batch_size} "
            f"rows per batch, {trainer.num_demos} demonstration rows "
            f"(label ratio {config.label_ratio:g})",
            flush=True,
        )
        with ticking("compiling"):
            grid = Grid(trainer, inputs, chunk_blocks)
        print(f"compiled in {grid.compile_seconds:.1f} s", flush=True)
        state, progress = start(grid, None)
        steps_per_chunk = grid.num_cells * grid.iterations_per_chunk
        steps_per_chunk *= trainer_config.steps_per_iteration
        num_chunks = trainer_config.num_evaluations // chunk_blocks

        def line(progress, metrics) -> str:
            done = progress.chunks_done * grid.iterations_per_chunk
            done *= trainer_config.steps_per_iteration
            rate = steps_per_chunk / progress.last_chunk_seconds
            final = report.normalize(metrics["eval/return"][:, -1], normalizer)
            shown = final if normalizer is not None else metrics["eval/return"][:, -1]
            best = int(np.nanargmax(shown)) if np.isfinite(shown).any() else 0
            left = (num_chunks - progress.chunks_done) * progress.last_chunk_seconds
            return (
                f"step {done:9,d}/{config.gradient_steps:,}  {rate:9,.0f} gradient steps/s "
                f"(all cells)  ETA {format_seconds(left)}  best {cells[best].method}/seed "
                f"{cells[best].seed} {shown[best]:.2f}"
            )

        start_time = time.perf_counter()
        run_chunks(grid, state, progress, num_chunks, steps_per_chunk=steps_per_chunk, line=line)
        summary = _write_outputs(out, config, cells, grid, progress, normalizer, trainer)
        write_json(
            out / "config.json",
            {
                "program": PROGRAM,
                "config": _json_config(config),
                "trainer": _json_config(trainer_config),
                "demonstrations": demos_path,
                "input_files": input_files(run_config, demos_path),
                "normalizer": normalizer,
                "normalizer_source": normalizer_source,
                "wall_seconds": time.perf_counter() - start_time,
                "provenance": provenance(program=PROGRAM),
            },
        )
    print(f"-> {out}/{{config.json,metrics.csv,summary.md,summary.json,curves.png}}")
    return summary


def _json_config(config) -> dict:
    values = dataclasses.asdict(config)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}


def _write_outputs(out, config, cells, grid, progress, normalizer, trainer) -> dict:
    """metrics.csv (``env_steps`` 0: no environment step is taken), summary.json / .md and
    curves.png; returns the summary."""
    metrics = {**progress.metrics, **progress.init_metrics}
    metrics["env_steps"] = np.zeros_like(progress.metrics["gradient_steps"], np.int64)
    chunk_seconds = progress.timing["chunk_seconds"]
    report.write_metrics_csv(out / "metrics.csv", cells, metrics, normalizer, chunk_seconds)
    excluded = nonfinite_cells(progress.metrics, trainer.config.eval_every)
    seconds = max(progress.timing["seconds"], 1e-9)
    baseline = "bc-all" if "bc-all" in config.methods else None
    summary = report.summarize(cells, metrics, normalizer, 0.0, grid.compile_seconds,
                               excluded, baseline)  # fmt: skip
    summary["gradient_steps"] = config.gradient_steps
    summary["gradient_steps_per_second"] = progress.timing["steps"] / seconds
    summary["offline/num_expert"] = float(np.mean(progress.init_metrics["offline/num_expert"]))
    title = (
        f"Offline methods on {config.env}: {config.gradient_steps:,} gradient steps, "
        f"{config.seeds} seeds"
    )
    notes = [
        f"Offline: no environment step; {summary['gradient_steps_per_second']:,.0f} gradient "
        f"steps/s over all {len(cells)} cells. Expert set: D_c's rows at confidence >= 0.5 "
        f"(mean {summary['offline/num_expert']:.0f} rows per seed)."
    ]
    markdown = report.summary_markdown(summary, cells, metrics, title, notes)
    report.write_summary(out, summary, markdown)
    gradient = {**metrics, "env_steps": progress.metrics["gradient_steps"]}
    report.plot_curves(out / "curves.png", cells, gradient, normalizer, title, excluded,
                       xlabel="M gradient steps per run")  # fmt: skip
    print(markdown)
    return summary
