"""``run(config, out)``: a sweep's lifecycle, as named steps.

    from pngail_jax import RunConfig, run

    result = run(RunConfig.preset("check", demos="data/released/Pendulum-v1_mixture.npy"),
                 "runs/first")
    result.table()          # per method: final return, mean, s.e., IQM and its 95% interval
    result.files["curves"]  # runs/first/curves.png

One call holds what ``python -m experiments.sweep`` does after reading its flags:

1. ``claim``: the output directory (new, empty, or the sweep's own run with ``overwrite``;
   ``pngail_jax.storage.outputs.claimed``) and its lock; a resume's checks of its saved config and
   input files (``record``) before the minutes of compiling.
2. ``build``: environment, demonstrations, trainer and the compiled ``Grid`` (``build``).
3. ``record``: config.json with its seal (``record.write_config``), for a new run.
4. ``start``: the grid's state, fresh or from the last intact checkpoint (``chunks``).
5. ``train``: the chunks, each with its progress line, checkpoint and partial outputs
   (``chunks.run_chunks``), with the config's tracking backends open.
6. ``finish``: the policies and the final outputs (``results``).

A refusal is a ``RunError`` whose message is one line; the program prints it. Process set-up
stays with the caller, because it must come before JAX starts its backend: XLA CPU devices
(``RunConfig.cpu_devices``, ``configure_devices``), the compilation cache and
``jax.distributed`` for multi-host runs (every process calls ``run``; process 0 writes).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import numpy as np

from pngail_jax.analysis.report import normalize
from pngail_jax.analysis.tracking import open_logger
from pngail_jax.config.run_config import RunConfig
from pngail_jax.grid import nonfinite_cells
from pngail_jax.jobs import record, results
from pngail_jax.jobs.build import BuiltRun, build_run
from pngail_jax.jobs.chunks import (
    Progress,
    format_seconds,
    intact_checkpoint,
    run_chunks,
    start,
)
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.results import RunResult
from pngail_jax.storage.outputs import claimed

PROGRAM = "sweep"  # the owner its directories are marked with (pngail_jax.storage.outputs)


def configure_devices(requested: int | None) -> None:
    """Splits the CPU into ``requested`` XLA devices (before JAX starts its backend).

    Not by default: benchmarks/grid_throughput.py measured a 35-cell grid on 2 cores at
    89.9k steps/s on one device and 90.9k on two (one XLA CPU device already uses every core).
    """
    if requested is not None and requested > 1:
        jax.config.update("jax_num_cpu_devices", requested)


def run(
    config: RunConfig | None,
    out: str | os.PathLike,
    *,
    resume: bool = False,
    overwrite: bool = False,
    allow_changed_inputs: bool = False,
    allow_unsealed: bool = False,
    command: Sequence[str] | None = None,
    saved: record.SavedRun | None = None,
) -> RunResult | None:
    """Trains ``config``'s grid into ``out`` and returns its result (None in a process of a
    multi-host run other than process 0, which writes).

    ``resume``: continue the run in ``out`` from its last intact checkpoint, with the config
    its ``config.json`` holds (``config`` must then be None or that same config; ``saved``
    passes it when the caller has read it already, with ``record.load_saved``).
    ``overwrite``: replace a finished or unfinished run of the sweep in ``out``.
    ``allow_changed_inputs``: resume although a demonstration file changed since the run
    began (``config.demos`` None: they are made once and cached, ``jobs.demonstrations``).
    ``allow_unsealed``: resume a run whose config seal is missing, its config unchecked.
    ``command``: the command line recorded in ``config.json`` (default: this process's).
    Raises ``RunError`` naming the problem (before any computation where it can be seen then).
    """
    out = Path(out)
    config, saved = _config_to_run(config, out, resume, saved, allow_unsealed)
    _warn_on_devices(config)
    writer = jax.process_index() == 0
    steps = _Steps(config, out, saved, writer, overwrite, allow_changed_inputs, command)
    if not writer:  # another host of a multi-host run: process 0 holds the lock
        return steps.run(claim=None)
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite, resume=saved is not None) as claim:
        return steps.run(claim)


def _config_to_run(config, out: Path, resume: bool, saved, allow_unsealed: bool = False):
    """The config a run trains (a resumed run's own) and its saved record (None if new)."""
    if resume:
        saved = saved or record.load_saved(out, allow_unsealed)
        given = None if config is None else record.resume_comparable(record.as_saved(config, saved))
        if given is not None and given != record.resume_comparable(saved.config):
            raise RunError(
                f"resume {out}: the config given differs from the run's config.json; pass None "
                "to continue the run as it began"
            )
        if saved.device_count != len(jax.devices()):
            print(
                f"WARNING: resuming on {len(jax.devices())} devices, the run began on "
                f"{saved.device_count}: a different sharding can change the last bits, and "
                "the rest of the run with them"
            )
        return saved.config, saved
    if config is None:
        raise RunError("run: give a RunConfig (or resume=True to continue the run in out)")
    return record.absolute_paths(config), None


def _warn_on_devices(config: RunConfig) -> None:
    """``cpu_devices`` only takes effect before JAX starts (``configure_devices``, which the
    sweep calls): say so when this process has another count than the config asks for."""
    wanted = config.cpu_devices
    if wanted and jax.devices()[0].platform == "cpu" and wanted != jax.local_device_count():
        print(
            f"WARNING: the config asks for {wanted} CPU devices and this process has "
            f"{jax.local_device_count()}: call pngail_jax.jobs.sweep.configure_devices("
            f"{wanted}) before anything runs on JAX, or set cpu_devices=None"
        )


class _Steps:
    """A run's steps after its claim, in order (``run``)."""

    def __init__(self, config, out, saved, writer, overwrite, allow_changed_inputs, command):
        self.config, self.out, self.saved, self.writer = config, out, saved, writer
        self.overwrite, self.allow_changed_inputs = overwrite, allow_changed_inputs
        self.command = command

    def run(self, claim) -> RunResult | None:
        checkpoint = None
        if self.saved is not None:  # these checks before the minutes of compiling
            record.check_inputs(self.saved, self.allow_changed_inputs)
            if record.already_complete(self.out):
                print(f"{self.out}: the run is already complete; nothing to do")
                return results.read_result(self.out) if self.writer else None
            checkpoint = intact_checkpoint(self.out / "checkpoints")
        built = build_run(self.config, self.saved)
        if claim is not None and self.saved is None:
            claim.prepare()  # an old run (overwrite) kept until the new one is built
            record.write_config(self.out, built, self.command)
        print(f"-> {self.out}", flush=True)
        state, progress = self.start(built, checkpoint)
        start_time = time.perf_counter()
        host_state = self.train(built, state, progress)
        return self.finish(built, host_state, progress, start_time)

    def start(self, built: BuiltRun, checkpoint: Path | None):
        """The grid's state and progress, fresh (saying how the classifiers did) or from
        ``checkpoint``; a resume drops outputs newer than its checkpoint."""
        phase_start = time.perf_counter()
        state, progress = start(built.grid, checkpoint)
        if checkpoint is None:
            mae = progress.init_metrics["confidence/mae"]
            print(
                f"classifier phase done in {time.perf_counter() - phase_start:.1f} s "
                "(confidence MAE on D_u: "
                + ", ".join(
                    f"{m} {np.mean(mae[[c.method == m for c in built.cells]]):.3f}"
                    for m in built.config.methods
                )
                + ")",
                flush=True,
            )
        if self.writer and self.saved is not None:
            record.drop_stale_outputs(self.out, progress.iterations_done(built.grid))
        return state, progress

    def train(self, built: BuiltRun, state, progress: Progress):
        """The remaining chunks, with the config's tracking backends open (process 0)."""
        config, grid, out = built.config, built.grid, self.out
        logger = None
        if self.writer and config.log:
            logger = open_logger(out, config.log, config.to_dict(), out.name)
        reported_bad: set[int] = set()

        def line(progress, metrics) -> str:
            return _progress_line(built, progress, metrics, reported_bad)

        def after(state, host_state, chunk_metrics) -> None:
            iteration = progress.iterations_done(grid)
            if logger is not None:
                first = iteration - grid.iterations_per_chunk + 1
                logger.log_chunk(built.cells, chunk_metrics, first)
            if self.writer and iteration < config.iterations:  # partial; the last below
                results.write_outputs(out, built, progress)

        try:
            state, host_state = run_chunks(
                grid,
                state,
                progress,
                config.iterations // grid.iterations_per_chunk,
                steps_per_chunk=len(built.cells)
                * grid.iterations_per_chunk
                * config.settings.samples_per_iteration,
                line=line,
                checkpoints=out / "checkpoints",
                writer=self.writer,
                after=after,
            )
        finally:
            if logger is not None:
                logger.close()
        return grid.fetch(state) if host_state is None else host_state

    def finish(self, built: BuiltRun, host_state, progress: Progress, start_time: float):
        """The policies (every process) and the final outputs (the writer)."""
        results.export_policies(self.out, built, host_state, progress, self.writer)
        if not self.writer:
            return None
        markdown = results.write_outputs(self.out, built, progress)
        print()
        print(markdown.split("\n\nFinal return")[0])
        print(
            f"\ndone in {format_seconds(time.perf_counter() - start_time)} (+ compile); wrote "
            f"{self.out}/{{config.json,metrics.csv,curves.png,diagnostics.png,summary.md,"
            "summary.json,policies/,checkpoints/}"
        )
        return results.read_result(self.out)


def _progress_line(built: BuiltRun, progress: Progress, chunk_metrics, reported_bad) -> str:
    """A chunk's progress line, after a line for each cell newly diverged (``reported_bad``,
    the cells already reported, grows)."""
    config = built.config
    iteration = progress.iterations_done(built.grid)
    bad = set(nonfinite_cells(progress.metrics, config.settings.eval_every).tolist())
    lines = [
        f"  ! cell {built.cells[i].method} seed {built.cells[i].seed} "
        f"({built.cells[i].setting}) diverged (NaN/inf)"
        for i in sorted(bad - reported_bad)
    ]
    reported_bad |= bad
    num_chunks = config.iterations // built.grid.iterations_per_chunk
    rate = progress.timing["steps"] / progress.timing["seconds"]
    remaining = (num_chunks - progress.chunks_done) * progress.timing["seconds"]
    remaining /= progress.chunks_done
    lines.append(
        f"iter {iteration:5d}/{config.iterations}  env steps "
        f"{iteration * config.settings.samples_per_iteration:,}/run  {rate:,.0f} steps/s  "
        f"ETA {format_seconds(remaining)}  "
        f"best {_best_cell(built.cells, chunk_metrics, built.return_range)}"
    )
    return "\n".join(lines)


def _best_cell(cells, chunk_metrics, return_range) -> str:
    final = chunk_metrics["eval/return"][:, -1]
    if not np.isfinite(final).any():
        return "(none finite)"
    index = int(np.nanargmax(final))
    cell = cells[index]
    normalized = normalize(final[index], return_range)
    extra = f" ({normalized:.2f})" if np.isfinite(normalized) else ""
    return f"{cell.method}/seed {cell.seed} {final[index]:.1f}{extra}"
