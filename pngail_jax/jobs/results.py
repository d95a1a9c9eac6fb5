"""A sweep's outputs: metrics.csv, curves.png, diagnostics.png, summary.json and summary.md
(partial while the run goes, final at its end), its policies, and ``RunResult``, what
``run`` returns."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import numpy as np

from pngail_jax.analysis import plots, report
from pngail_jax.config.run_config import RunConfig
from pngail_jax.grid import nonfinite_cells
from pngail_jax.jobs.build import BuiltRun
from pngail_jax.jobs.chunks import Progress
from pngail_jax.storage.checkpoint import save_trpo_policies
from pngail_jax.storage.integrity import read_json

OUTPUT_FILES = {
    "config": "config.json",
    "metrics": "metrics.csv",
    "curves": "curves.png",
    "diagnostics": "diagnostics.png",
    "summary_md": "summary.md",
    "summary": "summary.json",
    "policies": "policies",
    "checkpoints": "checkpoints",
}


@dataclasses.dataclass(frozen=True)
class RunResult:
    """A finished run: where it wrote, its summary (``summary.json``'s content) and its
    ``summary.md`` text; ``files`` maps each output to its path."""

    out: Path
    summary: dict
    markdown: str

    @property
    def files(self) -> dict[str, Path]:
        return {name: self.out / file for name, file in OUTPUT_FILES.items()}

    def table(self, metric: str = f"{report.HEADLINE}_normalized_return") -> list[dict]:
        """One row per method (and setting) of ``metric`` across seeds: by default the
        headline, ``late_average_normalized_return`` (the mean over the last
        ``report.LATE_SHARE`` of training, normalised); ``final_return`` (the last
        evaluation), ``average_return`` (all of training), ``late_average_return``, or their
        ``*_normalized_return`` forms. Each row: ``group``, ``mean``, ``se`` (standard
        error), ``iqm`` and ``ci95`` (its 95% bootstrap interval), ``seeds``."""
        rows = []
        for group, row in self.summary["methods"].items():
            if f"{metric}_mean" not in row:
                known = sorted(k.removesuffix("_mean") for k in row if k.endswith("_mean"))
                raise KeyError(f"no metric {metric!r} in the summary; it has {known}")
            rows.append(
                {
                    "group": group,
                    **{part: row[f"{metric}_{part}"] for part in ("mean", "se", "iqm", "ci95")},
                    "seeds": row.get("num_seeds"),
                }
            )
        return rows


def title_of(config: RunConfig, num_cells: int) -> str:
    return f"{config.env}: {num_cells} runs, {config.iterations} iterations"


def write_outputs(out: Path, run: BuiltRun, progress: Progress) -> str:
    """metrics.csv, curves.png, diagnostics.png, summary.json and summary.md of the iterations
    done so far
    (summary.json's ``complete`` is false and ``iterations_done`` says how far until the run
    ends); returns summary.md's text."""
    config, cells = run.config, run.cells
    metrics = {**progress.metrics, **progress.init_metrics}
    chunk_seconds = progress.timing.get("chunk_seconds", [])
    known = chunk_seconds if None not in chunk_seconds else ()
    report.write_metrics_csv(out / "metrics.csv", cells, metrics, run.return_range, known)
    title = title_of(config, len(cells))
    diverged = nonfinite_cells(progress.metrics, config.settings.eval_every)
    plots.plot_curves(out / "curves.png", cells, metrics, run.return_range, title, diverged)
    plots.plot_diagnostics(out / "diagnostics.png", cells, metrics, title, diverged)
    done = progress.iterations_done(run.grid)
    summary = {
        "complete": done == config.iterations,
        "iterations_done": done,
        "iterations": config.iterations,
        **report.summarize(
            cells,
            metrics,
            run.return_range,
            progress.timing["steps"] / progress.timing["seconds"],
            run.grid.compile_seconds,
            excluded=diverged,
            baseline=config.baseline,
        ),
    }
    notes = [
        f"Diverged (NaN/inf), left out of the statistics: {cells[i].method} seed "
        f"{cells[i].seed} ({cells[i].setting})."
        for i in diverged
    ]
    if done < config.iterations:
        notes.append(f"Partial: {done} of {config.iterations} iterations so far.")
    if config.iterations < 1000:
        notes.append(
            f"A reduced budget ({config.iterations} iterations); the paper's is "
            "`--preset paper` (5,000 iterations, GPU)."
        )
    markdown = report.summary_markdown(summary, cells, metrics, title, notes)
    report.write_summary(out, summary, markdown)
    return markdown


def export_policies(out: Path, run: BuiltRun, host_state, progress: Progress, writer: bool):
    """policies/<method>/ (and /<setting>/ when the grid has several): every seed's final
    policy, loadable with ``pngail_jax.load_policy`` (best seed by default; diverged seeds
    never are). Every process calls it (orbax synchronises them); the writer writes the JSON."""
    final_returns = progress.metrics["eval/return"][:, -1].copy()
    final_returns[nonfinite_cells(progress.metrics, run.config.settings.eval_every)] = np.nan
    trpo_state = run.trainer.policy_state(host_state)
    settings, groups = report.group_cells(run.cells)
    written = []
    for rows in groups.values():
        method, setting = run.cells[rows[0]].method, run.cells[rows[0]].setting
        directory = out / "policies" / method
        if len(settings) > 1:
            directory = directory / setting
        seeds_state = jax.tree.map(lambda x, rows=rows: x[np.asarray(rows)], trpo_state)
        extra = {
            "method": method,
            "setting": setting,
            "seeds": [run.cells[i].seed for i in rows],
            "env_options": run.config.settings.env_options,
        }
        written.append(
            save_trpo_policies(
                directory,
                run.env,
                run.trainer.config.rollout,
                seeds_state,
                final_returns[rows],
                extra,
                write_metadata=writer,
            )  # fmt: skip
        )
    return written


def read_result(out: Path) -> RunResult:
    summary = read_json(out / OUTPUT_FILES["summary"], "run summary")
    return RunResult(out, summary, (out / OUTPUT_FILES["summary_md"]).read_text())
