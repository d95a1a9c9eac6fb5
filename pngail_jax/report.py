"""Normalised returns, per-cell CSV rows, the summary tables and the learning-curve plot.

Everything here works on host arrays: ``metrics`` maps names to float[G, I] (cells x
iterations, as ``pngail_jax.grid`` returns them) and ``cells`` lists the G ``Cell``s.
"""

from __future__ import annotations

import csv
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

CSV_COLUMNS = (
    "method",
    "seed",
    "setting",
    "iteration",
    "env_steps",
    "eval_return",
    "normalized_return",
    "disc_acc_agent",
    "disc_acc_demo",
    "mean_reward",
    "kl",
    "train_return",
)
_METRIC_OF_COLUMN = {
    "env_steps": "env_steps",
    "eval_return": "eval/return",
    "disc_acc_agent": "disc/acc_agent",
    "disc_acc_demo": "disc/acc_demo",
    "mean_reward": "train/reward",
    "kl": "trpo/kl",
    "train_return": "train/episode_return",
}


def normalize(returns, normalizer: tuple[float, float] | None):
    """(R - R_random) / (R_optimal - R_random); NaN when no normaliser is known."""
    returns = np.asarray(returns, np.float64)
    if normalizer is None:
        return np.full_like(returns, np.nan)
    random_return, optimal_return = normalizer
    return (returns - random_return) / (optimal_return - random_return)


def _format(value) -> str:
    return "" if not np.isfinite(value) else f"{value:.6g}"


def write_metrics_csv(path: Path, cells, metrics, normalizer) -> None:
    """One row per cell and iteration; empty fields where a value is undefined (NaN)."""
    normalized = normalize(metrics["eval/return"], normalizer)
    num_iterations = metrics["env_steps"].shape[1]
    with Path(path).open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(CSV_COLUMNS)
        for index, cell in enumerate(cells):
            for iteration in range(num_iterations):
                values = {
                    column: _format(metrics[name][index, iteration])
                    for column, name in _METRIC_OF_COLUMN.items()
                }
                values["env_steps"] = str(int(metrics["env_steps"][index, iteration]))
                values["normalized_return"] = _format(normalized[index, iteration])
                writer.writerow(
                    [cell.method, cell.seed, cell.setting, iteration + 1]
                    + [values[column] for column in CSV_COLUMNS[4:]]
                )


def group_label(cell, settings: Sequence[str]) -> str:
    """The method's name, plus its setting when the grid has more than one."""
    return cell.method if len(settings) == 1 else f"{cell.method} [{cell.setting}]"


def _groups(cells):
    settings = list(dict.fromkeys(cell.setting for cell in cells))
    groups: dict[str, list[int]] = {}
    for index, cell in enumerate(cells):
        groups.setdefault(group_label(cell, settings), []).append(index)
    return settings, groups


def _mean_std(values):
    values = np.asarray(values, np.float64)
    finite = values[np.isfinite(values)]
    if len(finite) == 0:
        return float("nan"), float("nan")
    return float(finite.mean()), float(finite.std())


def summarize(cells, metrics, normalizer, train_env_steps_per_second, compile_seconds, excluded=()):
    """The ``summary.json`` dictionary. Final return: the last iteration's evaluation.

    Cells listed in ``excluded`` (diverged ones, ``pngail_jax.grid.nonfinite_cells``) and
    non-finite final returns are left out of the means and of ``num_seeds``.
    """
    final = np.asarray(metrics["eval/return"], np.float64)[:, -1].copy()
    final[list(excluded)] = np.nan
    final_normalized = normalize(final, normalizer)
    _, groups = _groups(cells)
    methods = {}
    for label, indices in groups.items():
        mean, std = _mean_std(final[indices])
        normalized_mean, normalized_std = _mean_std(final_normalized[indices])
        methods[label] = {
            "final_return_mean": mean,
            "final_return_std": std,
            "final_normalized_return_mean": normalized_mean,
            "final_normalized_return_std": normalized_std,
            "num_seeds": int(np.isfinite(final[indices]).sum()),
        }
    return {
        "methods": methods,
        "train_env_steps_per_second": float(train_env_steps_per_second),
        "compile_seconds": float(compile_seconds),
    }


def summary_markdown(summary, cells, metrics, title: str, notes: Sequence[str] = ()) -> str:
    """A Markdown table of ``summary`` plus the classifier's error per method."""
    _, groups = _groups(cells)
    lines = [
        f"# {title}",
        "",
        "| method | final return | normalised | seeds | confidence MAE (D_u) |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, row in summary["methods"].items():
        mae = np.asarray(metrics["confidence/mae"])[groups[label]]
        lines.append(
            f"| {label} | {row['final_return_mean']:.1f} ± {row['final_return_std']:.1f} | "
            f"{row['final_normalized_return_mean']:.2f} ± "
            f"{row['final_normalized_return_std']:.2f} | {row['num_seeds']} | "
            f"{np.nanmean(mae):.3f} |"
        )
    lines += [
        "",
        "Final return: deterministic (mean-action) evaluation at the last iteration, mean ± "
        "std over seeds. Confidence MAE: the confidences the method's loss uses on the "
        "unlabelled rows (GAIL and WGAIL read none; IC-GAIL reads only D_c's given ones, so "
        "its value is that of the mean labelled confidence, which it never reads).",
        "",
        f"Training throughput: {summary['train_env_steps_per_second']:,.0f} env steps/s "
        f"(adversarial phase, all cells); compile {summary['compile_seconds']:.1f} s.",
    ]
    lines += [f"\n{note}" for note in notes]
    return "\n".join(lines) + "\n"


def write_summary(directory: Path, summary: dict, markdown: str) -> None:
    (Path(directory) / "summary.json").write_text(json.dumps(summary, indent=2))
    (Path(directory) / "summary.md").write_text(markdown)


def plot_curves(path: Path, cells, metrics, normalizer, title: str) -> None:
    """Normalised evaluation return vs environment steps: mean ± std band per method (one
    panel per setting), like the paper's Fig. 2. Falls back to raw returns without a
    normaliser."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    returns = np.asarray(metrics["eval/return"], np.float64)
    values = normalize(returns, normalizer) if normalizer is not None else returns
    evaluated = ~np.isnan(returns).all(axis=0)
    settings = list(dict.fromkeys(cell.setting for cell in cells))
    methods = list(dict.fromkeys(cell.method for cell in cells))
    colors = dict(zip(methods, plt.get_cmap("tab10").colors, strict=False))
    figure, axes = plt.subplots(
        1, len(settings), figsize=(7 * len(settings), 4.8), squeeze=False, sharey=True
    )
    for axis, setting in zip(axes[0], settings, strict=True):
        for method in methods:
            rows = [i for i, c in enumerate(cells) if c.method == method and c.setting == setting]
            steps = np.asarray(metrics["env_steps"])[rows[0], evaluated]
            curve = values[rows][:, evaluated]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                mean, std = np.nanmean(curve, axis=0), np.nanstd(curve, axis=0)
            axis.plot(steps, mean, color=colors[method], lw=1.8, label=method)
            axis.fill_between(steps, mean - std, mean + std, color=colors[method], alpha=0.15)
        if normalizer is not None:
            axis.axhline(1.0, color="grey", ls="--", lw=0.8)
            axis.axhline(0.0, color="grey", ls=":", lw=0.8)
        axis.set(
            xlabel="environment steps (per run)",
            ylabel="normalised return" if normalizer is not None else "return",
            title=setting if len(settings) > 1 else None,
        )
        axis.grid(alpha=0.3)
    axes[0][-1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
