"""Normalised returns, per-cell CSV rows, the summary tables and the learning-curve plot.

Everything here works on host arrays: ``metrics`` maps names to float[G, I] (cells x
iterations, as ``pngail_jax.grid`` returns them) and ``cells`` lists the G ``Cell``s.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pngail_jax import stats
from pngail_jax.integrity import atomic_path, atomic_write_text, write_json

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


# summary.json's reading of null: JSON has no NaN, and a statistic can be undefined.
NULL_MEANS = (
    "undefined: no finite value to compute it from (every seed diverged, see diverged_seeds), "
    "a normalised return without random/optimal returns, or a spread of fewer than two seeds"
)


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
    with atomic_path(path) as temporary, temporary.open("w", newline="") as file:
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


def group_cells(cells) -> tuple[list[str], dict[str, list[int]]]:
    """The grid's settings, and each group's cell indices by its ``group_label``, in order."""
    settings = list(dict.fromkeys(cell.setting for cell in cells))
    groups: dict[str, list[int]] = {}
    for index, cell in enumerate(cells):
        groups.setdefault(group_label(cell, settings), []).append(index)
    return settings, groups


# "late average": the mean over the evaluations in this last share of training, our reading of
# the paper's Table 4 "average reward after training convergence".
LATE_SHARE = 0.1


def late_evaluations(num_evaluations: int) -> int:
    """How many of ``num_evaluations`` (evenly spaced) evaluations make the last
    ``LATE_SHARE`` of training: ``ceil(LATE_SHARE * num_evaluations)``, at least 1."""
    return max(1, math.ceil(LATE_SHARE * num_evaluations - 1e-9))


def _per_cell(cells, metrics, normalizer, excluded):
    """float64[G] per cell: final, training-averaged and late-averaged (the last
    ``LATE_SHARE`` of the evaluations) returns, raw and normalised; NaN for excluded cells."""
    returns = np.asarray(metrics["eval/return"], np.float64)
    evaluated = ~np.isnan(returns).all(axis=0)
    final = returns[:, -1].copy()
    columns = np.flatnonzero(evaluated)
    late_columns = columns[len(columns) - late_evaluations(len(columns)) :]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        average = np.nanmean(returns[:, columns], axis=1) if columns.size else final * np.nan
        late = np.nanmean(returns[:, late_columns], axis=1) if columns.size else final * np.nan
    values = {"final_return": final, "average_return": average, "late_average_return": late}
    for name in list(values):
        values[name][list(excluded)] = np.nan
        values[name.replace("_return", "_normalized_return")] = normalize(values[name], normalizer)
    return values


def summarize(cells, metrics, normalizer, train_env_steps_per_second, compile_seconds, excluded=()):
    """The ``summary.json`` dictionary (NaN where undefined; ``write_summary`` writes null).

    Per method (and setting): the final return (the last evaluation) and the average
    evaluation return over training, raw and normalised, as mean, sample std (ddof 1) and
    standard error over seeds (and the confidence classifier's MAE and RMSE on D_u, mean and
    std, when ``metrics`` has them), and as interquartile mean with a 95% percentile-bootstrap
    interval (``pngail_jax.stats``, fixed seed: the same numbers on every
    call), and a per-seed table (with the classifier's errors, which tell
    a seed's labels apart). Cells in ``excluded`` (diverged,
    ``pngail_jax.grid.nonfinite_cells``) and non-finite returns are left out of every
    statistic and of ``num_seeds``. With PN-GAIL in the grid: the probability that a PN-GAIL
    seed's final return beats a baseline seed's, per baseline, with its 95% interval.
    """
    excluded = set(excluded)
    values = _per_cell(cells, metrics, normalizer, excluded)
    settings, groups = group_cells(cells)
    methods = {}
    for label, indices in groups.items():
        row = {}
        for name, per_cell in values.items():
            summary = stats.seed_summary(per_cell[indices])
            row[f"{name}_mean"], row[f"{name}_std"] = summary["mean"], summary["std"]
            row[f"{name}_se"] = summary["se"]
            row[f"{name}_iqm"], row[f"{name}_ci95"] = summary["iqm"], summary["ci95"]
        for name in ("mae", "rmse"):  # the classifier's error on D_u (NaN: no classifier)
            if f"confidence/{name}" in metrics:
                error = stats.seed_summary(np.asarray(metrics[f"confidence/{name}"])[indices])
                row[f"confidence_{name}_mean"] = error["mean"]
                row[f"confidence_{name}_std"] = error["std"]
        row["num_seeds"] = int(np.isfinite(values["final_return"][indices]).sum())
        row["diverged_seeds"] = [cells[i].seed for i in indices if i in excluded]
        if row["num_seeds"] == 0:
            row["note"] = "no seed has a finite return (diverged, NaN/inf): statistics are null"
        errors = {
            f"confidence_{name}": np.asarray(metrics[f"confidence/{name}"])
            for name in ("mae", "rmse")
            if f"confidence/{name}" in metrics
        }
        row["per_seed"] = [
            {
                "seed": cells[i].seed,
                **{name: float(v[i]) for name, v in values.items()},
                **{name: float(v[i]) for name, v in errors.items()},
            }
            for i in indices
        ]
        methods[label] = row
    return {
        "null_means": NULL_MEANS,
        "methods": methods,
        "probability_of_improvement": _improvement_over_baselines(
            cells, settings, values["final_return"]
        ),
        "train_env_steps_per_second": float(train_env_steps_per_second),
        "compile_seconds": float(compile_seconds),
    }


def _improvement_over_baselines(cells, settings, final, method="pngail") -> dict:
    """``{baseline label: {"estimate", "ci95"}}``: P(a ``method`` seed's final return beats a
    baseline seed's) per setting (rliable's probability of improvement)."""
    result = {}
    for setting in settings:
        rows = {}
        for index, cell in enumerate(cells):
            if cell.setting == setting:
                rows.setdefault(cell.method, []).append(index)
        if method not in rows:
            continue
        ours = final[rows[method]]
        for baseline, indices in rows.items():
            if baseline == method:
                continue
            label = group_label(cells[indices[0]], settings)
            result[label] = {
                "estimate": stats.probability_of_improvement(ours, final[indices]),
                "ci95": list(stats.probability_of_improvement_ci(ours, final[indices])),
            }
    return result


def _interval(row, name: str, digits: int = 2) -> str:
    """IQM [95% CI] of the normalised ``name``, or of the raw one without a normaliser."""
    if not np.isfinite(row[f"{name}_iqm"]):
        name, digits = name.replace("_normalized", ""), 1
    low, high = row[f"{name}_ci95"]
    if not np.isfinite(row[f"{name}_iqm"]):
        return "n/a"
    return f"{row[f'{name}_iqm']:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _mean_se(row, name: str, digits: int) -> str:
    mean, se = row[f"{name}_mean"], row[f"{name}_se"]
    if not np.isfinite(mean):
        return "n/a"
    return f"{mean:.{digits}f}" + (f" ± {se:.{digits}f}" if np.isfinite(se) else "")


def summary_markdown(summary, cells, metrics, title: str, notes: Sequence[str] = ()) -> str:
    """Markdown tables of ``summary``: per method, per seed, and PN-GAIL's probability of
    improvement over each baseline."""
    _, groups = group_cells(cells)
    lines = [
        f"# {title}",
        "",
        "| method | final return | final normalised*: IQM [95% CI] | mean ± s.e. | "
        "average over the last 10%*: IQM [95% CI] | average over all of training*: "
        "IQM [95% CI] | seeds | confidence MAE (D_u) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, row in summary["methods"].items():
        mae = np.asarray(metrics["confidence/mae"])[groups[label]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mae_text = f"{np.nanmean(mae):.3f}" if np.isfinite(mae).any() else "n/a"
        lines.append(
            f"| {label} | {_mean_se(row, 'final_return', 1)} | "
            f"{_interval(row, 'final_normalized_return')} | "
            f"{_mean_se(row, 'final_normalized_return', 2)} | "
            f"{_interval(row, 'late_average_normalized_return')} | "
            f"{_interval(row, 'average_normalized_return')} | {row['num_seeds']} | {mae_text} |"
        )
    lines += [
        "",
        "Final return: deterministic (mean-action) evaluation at the last iteration; average "
        "over the last 10%: the mean of a seed's evaluations in the last tenth of training "
        "(our reading of the paper's Table 4 'average reward after training convergence'); "
        "average over all of training: the mean of every evaluation of a seed, from the "
        "first iteration on. Over seeds: interquartile mean with a 95% stratified-bootstrap "
        "interval "
        "(2,000 resamples), and mean ± standard error. *Raw returns (one decimal) where the "
        "demonstrations carry no random and optimal returns. Confidence MAE: the confidences the "
        "method's loss uses on the unlabelled rows (GAIL and WGAIL read none; IC-GAIL reads "
        "only D_c's given ones, so its value is that of the mean labelled confidence, which it "
        "never reads).",
    ]
    improvement = summary.get("probability_of_improvement", {})
    if improvement:
        lines += [
            "",
            "Probability of improvement: P(a PN-GAIL seed's final return > a baseline seed's), "
            "95% bootstrap interval.",
            "",
            "| over | P(PN-GAIL > baseline) | 95% CI |",
            "|---|---:|---:|",
        ]
        for label, value in improvement.items():
            low, high = value["ci95"]
            lines.append(f"| {label} | {value['estimate']:.2f} | [{low:.2f}, {high:.2f}] |")
    lines += [
        "",
        "Per seed:",
        "",
        "| method | seed | final return | normalised | last-10% average | normalised | "
        "average over training | normalised |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, row in summary["methods"].items():
        for seed in row["per_seed"]:
            numbers = tuple(
                seed[f"{kind}{scale}"]
                for kind in ("final", "late_average", "average")
                for scale in ("_return", "_normalized_return")
            )
            cells_text = " | ".join("n/a" if not np.isfinite(v) else f"{v:.2f}" for v in numbers)
            lines.append(f"| {label} | {seed['seed']} | {cells_text} |")
    lines += [
        "",
        f"Training throughput: {summary['train_env_steps_per_second']:,.0f} env steps/s "
        f"(adversarial phase, all cells); compile {summary['compile_seconds']:.1f} s.",
    ]
    lines += [f"\n{note}" for note in notes]
    return "\n".join(lines) + "\n"


def json_safe(value):
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(item) for item in value]
    if isinstance(value, float | np.floating) and not np.isfinite(value):
        return None
    return value


def write_summary(directory: Path, summary: dict, markdown: str) -> None:
    """summary.json (non-finite numbers as null) and summary.md, each written atomically."""
    write_json(Path(directory) / "summary.json", json_safe(summary))
    atomic_write_text(Path(directory) / "summary.md", markdown)


def plot_curves(path: Path, cells, metrics, normalizer, title: str, excluded=()) -> None:
    """Normalised evaluation return vs environment steps: the mean over seeds with its 95%
    bootstrap interval per method (one panel per setting), like the paper's Fig. 2. Falls
    back to raw returns without a normaliser. Cells in ``excluded`` (diverged) are left out,
    as from the summary."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    returns = np.asarray(metrics["eval/return"], np.float64)
    values = normalize(returns, normalizer) if normalizer is not None else returns
    evaluated = ~np.isnan(returns).all(axis=0)
    settings = list(dict.fromkeys(cell.setting for cell in cells))
    methods = list(dict.fromkeys(cell.method for cell in cells))
    excluded = set(excluded)
    colors = dict(zip(methods, plt.get_cmap("tab10").colors, strict=False))
    figure, axes = plt.subplots(
        1, len(settings), figsize=(7 * len(settings), 4.8), squeeze=False, sharey=True
    )
    for axis, setting in zip(axes[0], settings, strict=True):
        for method in methods:
            rows = [
                i
                for i, c in enumerate(cells)
                if c.method == method and c.setting == setting and i not in excluded
            ]
            if not rows:
                continue
            steps = np.asarray(metrics["env_steps"])[rows[0], evaluated]
            curve = values[rows][:, evaluated]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(curve, axis=0)
            low, high = np.array([stats.bootstrap_ci(column, np.mean) for column in curve.T]).T
            axis.plot(steps, mean, color=colors[method], lw=1.8, label=method)
            axis.fill_between(steps, low, high, color=colors[method], alpha=0.15)
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
    figure.suptitle(f"{title}\nmean over seeds; shaded: 95% bootstrap interval of the mean")
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)
