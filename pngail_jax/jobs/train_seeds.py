"""``train_seeds``: TRPO for stacked seeds, one compiled block of evaluations at a time, with a
progress line per block and (optionally) checkpoints it resumes from: what ``train_rl`` and
``make_demos`` run."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pngail_jax.grid import Grid
from pngail_jax.jobs.chunks import intact_checkpoint, nanmean, run_chunks, start


def train_seeds(trainer, hyperparams, keys, on_block=None, checkpoints: Path | None = None):
    """Runs ``trainer`` (a ``pngail_jax.rl.PolicyTrainer``) for stacked seeds, one compiled
    block of ``eval_every`` iterations at a time (``pngail_jax.grid.Grid``), printing
    progress after each.

    Calls ``on_block(iteration, trpo_state, block_metrics)`` if given (e.g. to keep
    checkpoints). With ``checkpoints`` (a directory), the whole state is saved there after
    every block (``chunk_NNNN/``, the last two kept), and a run that finds an intact one
    continues from it to the numbers of an uninterrupted run; ``on_block`` is then called
    first for the block restored (its policies may not have been kept: the run can be cut
    between a block's checkpoint and ``on_block``). The numbers are those of the
    whole-scan ``trainer.train``. Returns ``(final TRPOState, metrics)`` with metrics
    float[seeds, num_iterations].
    """
    config = trainer.config
    grid = Grid(trainer, (hyperparams, keys), blocks_per_chunk=1)
    print(f"compiled in {grid.compile_seconds:.1f} s", flush=True)
    found = None
    if checkpoints is not None and checkpoints.exists():
        found = intact_checkpoint(checkpoints)
    state, progress = start(grid, found)
    if on_block is not None and progress.chunks_done:
        block = {name: values[:, -config.eval_every :] for name, values in progress.metrics.items()}
        on_block(progress.iterations_done(grid), grid.fetch(trainer.policy_state(state)), block)

    def line(progress, metrics) -> str:
        rate = grid.num_cells * config.eval_every * config.batch_size
        rate /= progress.last_chunk_seconds
        final = metrics["eval/return"][:, -1]
        return (
            f"iter {progress.chunks_done * config.eval_every:5d}  "
            f"eval {np.mean(final):9.1f} [{', '.join(f'{r:.0f}' for r in final)}]  "
            f"train {nanmean(metrics['train/episode_return'][:, -1]):9.1f}  "
            f"{rate:10,.0f} steps/s"
        )

    def after(state, host_state, metrics) -> None:
        if on_block is not None:
            iteration = progress.chunks_done * config.eval_every
            on_block(iteration, grid.fetch(trainer.policy_state(state)), metrics)

    state, _ = run_chunks(
        grid,
        state,
        progress,
        config.num_evaluations,
        steps_per_chunk=grid.num_cells * config.eval_every * config.batch_size,
        line=line,
        checkpoints=checkpoints,
        after=after,
    )
    return grid.fetch(trainer.policy_state(state)), progress.metrics
