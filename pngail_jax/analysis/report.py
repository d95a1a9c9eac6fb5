"""Normalised returns, per-cell CSV rows, the summary tables and the learning-curve plot.

Everything here works on host arrays: ``metrics`` maps names to float[G, I] (cells x
iterations, as ``pngail_jax.grid`` returns them) and ``cells`` lists the G ``Cell``s.
"""

from __future__ import annotations

import csv
import gzip
import math
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.config.presets import display_name, reads_confidences
from pngail_jax.storage.integrity import atomic_path, atomic_write_text, write_json

CSV_COLUMNS = (
    "method",
    "seed",
    "setting",  # both grid axes in one label, e.g. "label_ratio=0.2,noise=0"
    "label_ratio",  # one column per grid axis
    "noise",  # then one column per further grid axis (RunConfig.grid_axes), if any
    "iteration",
    "env_steps",
    "wall_seconds",  # training seconds (compile excluded) when the iteration's chunk ended
    "eval_return",
    "normalized_return",
    "disc_acc_agent",
    "disc_acc_demo",
    "mean_reward",
    "kl",
    "train_return",
    "mean_abs_action",  # the policy's sampled actions: mean |a| over every entry
    "beyond_bounds",  # ... and the share of those entries outside the action bounds
)
_METRIC_OF_COLUMN = {
    "env_steps": "env_steps",
    "eval_return": "eval/return",
    "disc_acc_agent": "disc/acc_agent",
    "disc_acc_demo": "disc/acc_demo",
    "mean_reward": "train/reward",
    "kl": ("trpo/kl", "ppo/kl"),  # the policy step's mean KL, whichever learner made it
    "train_return": "train/episode_return",
    "mean_abs_action": "rollout/mean_abs_action",
    "beyond_bounds": "rollout/beyond_bounds",
}


def _metric_of(column: str, metrics) -> str | None:
    """The metric a metrics.csv column shows: the first of its names the run recorded
    (None: none, an empty column)."""
    names = _METRIC_OF_COLUMN[column]
    return next((n for n in ((names,) if isinstance(names, str) else names) if n in metrics), None)


# summary.json's reading of null: JSON has no NaN, and a statistic can be undefined.
NULL_MEANS = (
    "undefined: no finite value to compute it from (every seed diverged, see diverged_seeds), "
    "a normalised return without random/optimal returns, or a spread of fewer than two seeds"
)


def normalize(returns, return_range: tuple[float, float] | None):
    """(R - R_random) / (R_optimal - R_random); NaN when no return range is known."""
    returns = np.asarray(returns, np.float64)
    if return_range is None:
        return np.full_like(returns, np.nan)
    random_return, optimal_return = return_range
    return (returns - random_return) / (optimal_return - random_return)


def _format(value) -> str:
    return "" if not np.isfinite(value) else f"{value:.6g}"


def write_metrics_csv(
    path: Path, cells, metrics, return_range, chunk_seconds=(), extra_columns=None
) -> None:
    """One row per cell and iteration; empty fields where a value is undefined (NaN).

    ``chunk_seconds``: the cumulative training seconds at the end of each chunk (all cells run
    a chunk's iterations in one program, so that is the finest wall clock there is); an
    iteration gets its chunk's, empty where unknown (a run resumed from an older version).
    A list per cell instead (float[G][chunks]) gives each cell its own program's (the
    offline family runs its methods in several programs).
    A metric the run did not record (an appendix-only trainer, a checkpoint of an older
    version) leaves its column empty. ``extra_columns`` ({column: metric}) adds columns after
    ``CSV_COLUMNS`` (the offline program's ``offline.METRICS_CSV_COLUMNS``)."""
    normalized = normalize(metrics["eval/return"], return_range)
    num_iterations = metrics["env_steps"].shape[1]
    per_cell = bool(chunk_seconds) and isinstance(chunk_seconds[0], (list, tuple, np.ndarray))
    if not per_cell:
        chunk_seconds = [chunk_seconds] * len(cells)

    def wall_clock(seconds) -> list[str]:
        per_chunk = num_iterations // len(seconds) if len(seconds) else 0
        return [f"{seconds[i // per_chunk]:.1f}" if per_chunk and seconds[i // per_chunk]
                is not None else "" for i in range(num_iterations)]  # fmt: skip

    # A grid's further axes (grid_axes) get a column each, after label_ratio and noise.
    axes = list(dict.fromkeys(field for cell in cells for field, _ in cell.axes))
    columns = {column: _metric_of(column, metrics) for column in _METRIC_OF_COLUMN}
    extra = {column: name if name in metrics else None
             for column, name in (extra_columns or {}).items()}  # fmt: skip

    def rows():
        for index, cell in enumerate(cells):
            axis_values = dict(cell.axes)
            wall = wall_clock(chunk_seconds[index])
            for iteration in range(num_iterations):
                values = {
                    column: _format(metrics[name][index, iteration]) if name else ""
                    for column, name in (columns | extra).items()
                }
                values["env_steps"] = str(int(metrics["env_steps"][index, iteration]))
                values["normalized_return"] = _format(normalized[index, iteration])
                values["wall_seconds"] = wall[iteration]
                values["iteration"] = str(iteration + 1)
                values["label_ratio"] = f"{cell.label_ratio:g}"
                values["noise"] = f"{cell.noise_std:g}"
                yield (
                    [cell.method, cell.seed, cell.setting]
                    + [values[column] for column in CSV_COLUMNS[3:5]]
                    + [f"{axis_values[field]:g}" for field in axes]
                    + [values[column] for column in (*CSV_COLUMNS[5:], *extra)]
                )

    _write_csv(path, [*CSV_COLUMNS[:5], *axes, *CSV_COLUMNS[5:], *extra], rows())


def write_seed_metrics_csv(path: Path, metrics, columns: Sequence[str]) -> None:
    """``train_rl``'s metrics.csv: one row per seed and iteration, the metrics ``columns``
    under their own names (a learner on the true reward has no methods or settings)."""
    num_seeds, num_iterations = metrics["env_steps"].shape
    rows = (
        [seed, iteration + 1, *(f"{metrics[name][seed, iteration]:.6g}" for name in columns)]
        for seed in range(num_seeds)
        for iteration in range(num_iterations)
    )
    _write_csv(path, ["seed", "iteration", *columns], rows)


def _write_csv(path: Path, header: Sequence[str], rows) -> None:
    """The library's one writer of metrics files: ``header`` then ``rows``, atomically."""
    with atomic_path(path) as temporary, temporary.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(header)
        writer.writerows(rows)


def metrics_rows(path: Path) -> Iterator[dict[str, str]]:
    """Every row of a metrics file as a dict of its columns: ``metrics.csv`` (the sweep's,
    the offline program's or ``train_rl``'s), or ``metrics.csv.gz`` (a run record's,
    ``pngail_jax.analysis.run_records``). The library's one reader of metrics files."""
    path = Path(path)
    opened = gzip.open(path, "rt", newline="") if path.suffix == ".gz" else path.open(newline="")
    with opened as file:
        yield from csv.DictReader(file)


def read_evaluations(
    path: Path,
    value: str,
    *,
    evaluated_by: str | None = None,
    group_by: Sequence[str] = (),
    steps_per_iteration: int | None = None,
) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
    """The evaluations in a ``metrics.csv`` (the sweep's or ``train_rl``'s), per group (the
    values of the ``group_by`` columns, e.g. method and setting): the environment steps
    int[I] of the evaluated iterations (or, given ``steps_per_iteration``, the iteration
    times it: an offline run's gradient steps) and the ``value`` column float[seeds, I] (NaN
    where empty). A row counts as evaluated where its ``evaluated_by`` column (default:
    ``value``) is neither empty nor NaN; where a seed has no evaluated row at an iteration
    another seed has (the sweep leaves a diverged seed's returns empty), its value is NaN."""
    evaluated_by = evaluated_by or value
    rows: dict[tuple, dict[int, dict[int, float]]] = {}
    steps: dict[int, int] = {}
    for row in metrics_rows(path):
        marker = row[evaluated_by]
        if marker == "" or math.isnan(float(marker)):
            continue
        group = tuple(row[column] for column in group_by)
        number = float(row[value]) if row[value] else math.nan
        rows.setdefault(group, {}).setdefault(int(row["seed"]), {})[int(row["iteration"])] = number
        iteration = int(row["iteration"])
        steps[iteration] = (
            iteration * steps_per_iteration
            if steps_per_iteration is not None
            else int(float(row["env_steps"]))
        )
    evaluations = {}
    for group, seeds in rows.items():
        iterations = sorted({i for evaluated in seeds.values() for i in evaluated})
        evaluations[group] = (
            np.array([steps[i] for i in iterations]),
            np.array([[seeds[s].get(i, math.nan) for i in iterations] for s in sorted(seeds)]),
        )
    return evaluations


def iterations_per_cell(path: Path) -> dict[tuple[str, str, int], int]:
    """The highest iteration each cell (method, setting, seed) of a ``metrics.csv`` reached.
    The sweep writes every cell to the same iteration, so cells that differ mean a file cut
    short."""
    reached: dict[tuple[str, str, int], int] = {}
    for row in metrics_rows(path):
        cell = (row["method"], row["setting"], int(row["seed"]))
        reached[cell] = max(reached.get(cell, 0), int(row["iteration"]))
    return reached


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


# The headline figure of a run's final performance, the "late average": a seed's mean
# evaluation return over this last share of training. Chosen by measured re-run agreement
# (docs/sweep.md, "Which statistic a re-run does not overturn": two disjoint halves of a
# 10-seed grid order the methods alike at Kendall tau 0.68 under it, 0.48 under the final
# evaluation); also our reading of the paper's Table 4 "average reward after training
# convergence". The final evaluation stays beside it as a column.
LATE_SHARE = 0.2
HEADLINE = "late_average"  # the summary's, compare's and the records' leading statistic
LATE_LABEL = f"last {LATE_SHARE:.0%} of training"  # what tables call it


def late_evaluations(num_evaluations: int) -> int:
    """How many of ``num_evaluations`` (evenly spaced) evaluations make the last
    ``LATE_SHARE`` of training: ``ceil(LATE_SHARE * num_evaluations)``, at least 1."""
    return max(1, math.ceil(LATE_SHARE * num_evaluations - 1e-9))


def late_average(evaluations: np.ndarray) -> np.ndarray:
    """float[seeds] from float[seeds, evaluations] (every column evaluated, oldest first):
    each seed's mean over its last ``late_evaluations`` evaluations (NaN stays NaN)."""
    evaluations = np.asarray(evaluations, np.float64)
    return evaluations[:, evaluations.shape[1] - late_evaluations(evaluations.shape[1]) :].mean(1)


def seed_figures(evaluations: np.ndarray, statistic: str) -> np.ndarray:
    """float[seeds]: each seed's ``statistic`` of float[seeds, evaluations]: ``late_average``
    (the headline) or ``final`` (the last evaluation)."""
    if statistic == "final":
        return np.asarray(evaluations, np.float64)[:, -1]
    if statistic == "late_average":
        return late_average(evaluations)
    raise ValueError(f"statistic {statistic!r}: give late_average or final")


def _per_cell(cells, metrics, return_range, excluded):
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
        values[name.replace("_return", "_normalized_return")] = normalize(
            values[name], return_range
        )
    return values


# summary.json's key for the normalised return's ends, (random, optimal); the summaries
# written before it was named (issue 74) say "normalizer", and every reader takes both.
RETURN_RANGE_KEY = "return_range"
_OLD_RETURN_RANGE_KEY = "normalizer"


def summarize(
    cells,
    metrics,
    return_range,
    train_env_steps_per_second,
    compile_seconds,
    excluded=(),
    baseline: str | None = None,
):
    """The ``summary.json`` dictionary (NaN where undefined; ``write_summary`` writes null).

    Per method (and setting): the final return (the last evaluation) and the average
    evaluation return over training, raw and normalised, as mean, sample std (ddof 1) and
    standard error over seeds (and the confidence classifier's MAE and RMSE on D_u, mean and
    std, when ``metrics`` has them), and as interquartile mean with a 95% percentile-bootstrap
    interval (``pngail_jax.analysis.stats``, fixed seed: the same numbers on every
    call), and a per-seed table (with the classifier's errors, which tell
    a seed's labels apart). Cells in ``excluded`` (diverged,
    ``pngail_jax.grid.nonfinite_cells``) and non-finite returns are left out of every
    statistic and of ``num_seeds``. With PN-GAIL in the grid: the probability that a PN-GAIL
    seed's headline figure (``HEADLINE``: its mean over the last ``LATE_SHARE`` of training)
    beats a baseline seed's, per baseline, with its 95% interval, and the same on the final
    evaluation (``probability_of_improvement_final``); with ``baseline`` (a method), the
    probability that each other method's seed beats its seed.
    """
    excluded = set(excluded)
    values = _per_cell(cells, metrics, return_range, excluded)
    settings, groups = group_cells(cells)
    methods = {
        label: _method_row(cells, indices, values, metrics, excluded)
        for label, indices in groups.items()
    }
    return {
        "null_means": NULL_MEANS,
        "headline": {"statistic": HEADLINE, "late_share": LATE_SHARE},
        "methods": methods,
        "probability_of_improvement": _improvement_over_baselines(
            cells, settings, values[f"{HEADLINE}_return"], baseline
        ),
        "probability_of_improvement_final": _improvement_over_baselines(
            cells, settings, values["final_return"], baseline
        ),
        "improvement": {"over": baseline} if baseline else {"of": "pngail"},
        "train_env_steps_per_second": float(train_env_steps_per_second),
        "compile_seconds": float(compile_seconds),
        RETURN_RANGE_KEY: None if return_range is None else [float(x) for x in return_range],
    }


def summary_return_range(summary: dict) -> tuple[bool, object]:
    """(whether ``summary`` (a summary.json) states the normalised return's ends, what it
    states: [random, optimal], or None for a run without them), of either key."""
    for key in (RETURN_RANGE_KEY, _OLD_RETURN_RANGE_KEY):
        if key in summary:
            return True, summary[key]
    return False, None


def _method_row(cells, indices, values, metrics, excluded) -> dict:
    """One method's (and setting's) row of ``summarize``: each value's statistics over the
    seeds ``indices``, the classifier's errors, and the per-seed table."""
    row = {}
    for name, per_cell in values.items():
        summary = stats.seed_summary(per_cell[indices])
        row[f"{name}_mean"], row[f"{name}_std"] = summary["mean"], summary["std"]
        row[f"{name}_se"] = summary["se"]
        row[f"{name}_iqm"], row[f"{name}_ci95"] = summary["iqm"], summary["ci95"]
    errors = {  # the classifier's error on D_u (absent: no classifier)
        f"confidence_{name}": np.asarray(metrics[f"confidence/{name}"])
        for name in ("mae", "rmse")
        if f"confidence/{name}" in metrics
    }
    for name, per_cell in errors.items():
        error = stats.seed_summary(per_cell[indices])
        row[f"{name}_mean"], row[f"{name}_std"] = error["mean"], error["std"]
    row["num_seeds"] = int(np.isfinite(values["final_return"][indices]).sum())
    row["diverged_seeds"] = [cells[i].seed for i in indices if i in excluded]
    if row["num_seeds"] == 0:
        row["note"] = "no seed has a finite return (diverged, NaN/inf): statistics are null"
    row["per_seed"] = [
        {
            "seed": cells[i].seed,
            **{name: float(v[i]) for name, v in values.items()},
            **{name: float(v[i]) for name, v in errors.items()},
        }
        for i in indices
    ]
    return row


def _improvement_over_baselines(cells, settings, final, baseline: str | None = None) -> dict:
    """``{label: {"estimate", "ci95"}}`` per setting (rliable's probability of improvement):
    without ``baseline``, P(a PN-GAIL seed's figure in ``final`` (per cell) beats a seed of
    the labelled method); with it, P(a seed of the labelled method beats a ``baseline``
    seed)."""
    result = {}
    anchor = baseline or "pngail"
    for setting in settings:
        rows = {}
        for index, cell in enumerate(cells):
            if cell.setting == setting:
                rows.setdefault(cell.method, []).append(index)
        if anchor not in rows:
            continue
        fixed = final[rows[anchor]]
        for other, indices in rows.items():
            if other == anchor:
                continue
            label = group_label(cells[indices[0]], settings)
            ours, theirs = (final[indices], fixed) if baseline else (fixed, final[indices])
            result[label] = {
                "estimate": stats.probability_of_improvement(ours, theirs),
                "ci95": list(stats.probability_of_improvement_ci(ours, theirs)),
                "seeds": [len(ours), len(theirs)],
            }
    return result


def _interval(row, name: str, digits: int) -> str:
    """IQM [95% CI] over seeds; the one value and n = 1 for a single seed."""
    iqm = row[f"{name}_iqm"]
    if not np.isfinite(iqm):
        return "n/a"
    if row["num_seeds"] == 1:
        return f"{iqm:.{digits}f} (n = 1)"
    low, high = row[f"{name}_ci95"]
    return f"{iqm:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _mean_se(row, name: str, digits: int) -> str:
    """mean ± standard error over seeds (the one spread convention of every table here)."""
    mean, se = row[f"{name}_mean"], row[f"{name}_se"]
    if not np.isfinite(mean):
        return "n/a"
    if row["num_seeds"] == 1:
        return f"{mean:.{digits}f} (n = 1)"
    return f"{mean:.{digits}f}" + (f" ± {se:.{digits}f}" if np.isfinite(se) else "")


def summary_markdown(summary, cells, metrics, title: str, notes: Sequence[str] = ()) -> str:
    """Markdown tables of ``summary``: per method, per seed, and PN-GAIL's probability of
    improvement over each baseline. Normalised columns only when the run has a return range;
    no interval for a single seed; a classifier error only for methods that read
    confidences (``methods.reads_confidences``)."""
    _, groups = group_cells(cells)
    stated, return_range = summary_return_range(summary)
    if stated:  # what the run normalised by (finite values or not)
        normalised = return_range is not None
    else:
        normalised = any(
            np.isfinite(row["final_normalized_return_mean"]) for row in summary["methods"].values()
        )
    kind, digits = ("normalised return", 2) if normalised else ("return", 1)
    suffix = "_normalized_return" if normalised else "_return"
    header = (
        f"| method | seeds | {LATE_LABEL}, {kind}: IQM [95% CI] | {LATE_LABEL}, {kind}: "
        f"mean ± s.e. | final {kind}: IQM [95% CI] | "
        + (f"final {kind}: mean ± s.e. | " if normalised else "")
        + f"final return: mean ± s.e. | all of training, {kind}: IQM [95% CI] | "
        "confidence MAE on D_u |"
    )
    lines = [f"# {title}", "", header, "|---" + "|---:" * (header.count("|") - 2) + "|"]
    for label, row in summary["methods"].items():
        mae = np.asarray(metrics["confidence/mae"])[groups[label]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mae_text = f"{np.nanmean(mae):.3f}" if np.isfinite(mae).any() else "n/a"
        if not reads_confidences(cells[groups[label][0]].method):
            mae_text = "reads none"
        columns = [
            display_label(label),
            str(row["num_seeds"]),
            _interval(row, f"late_average{suffix}", digits),
            _mean_se(row, f"late_average{suffix}", digits),
            _interval(row, f"final{suffix}", digits),
            *([_mean_se(row, "final_normalized_return", 2)] if normalised else []),
            _mean_se(row, "final_return", 1),
            _interval(row, f"average{suffix}", digits),
            mae_text,
        ]
        lines.append("| " + " | ".join(columns) + " |")
    lines += ["", _table_note(normalised)]
    lines += _improvement_lines(summary)
    lines += _per_seed_lines(summary)
    throughput = summary["train_env_steps_per_second"]
    lines += [  # an offline grid takes no environment step: its notes give its throughput
        "",
        (
            f"Training throughput: {throughput:,.0f} env steps/s (adversarial phase, all cells); "
            if throughput
            else ""
        )
        + f"compile {summary['compile_seconds']:.1f} s.",
    ]
    lines += [f"\n{note}" for note in notes]
    return "\n".join(lines) + "\n"


def _table_note(normalised: bool) -> str:
    """What summary.md's main table's columns and spreads are."""
    return (
        f"The {LATE_LABEL} (the headline figure, first): the mean of a seed's "
        "deterministic (mean-action) evaluations in that share of training, the figure two "
        "re-runs agree on best (our reading, too, of the paper's Table 4 'average reward after "
        "training convergence'); final: the evaluation at the last iteration; all of "
        "training: the mean of every evaluation of a seed, from the first iteration on. Over "
        "seeds: interquartile mean with a 95% stratified-bootstrap interval (2,000 "
        "resamples), and mean ± standard error (s.e., sample std / sqrt(n)); n = 1: one seed, "
        "no interval. "
        + (
            "Normalised return: (R - R_random) / (R_optimal - R_random). "
            if normalised
            else "Raw returns: the demonstrations carry no random and optimal returns "
            "(give --optimal-return for normalised ones). "
        )
        + "Confidence MAE: the confidences the method's loss uses on the unlabelled rows "
        "(IC-GAIL reads only D_c's given ones, so its value is that of the mean labelled "
        "confidence, which it never reads)."
    )


def _improvement_lines(summary: dict) -> list[str]:
    """summary.md's table of PN-GAIL's probability of improvement over each baseline (or of
    each method's over the run's baseline), on the headline figure and on the final
    evaluation."""
    improvement = summary.get("probability_of_improvement", {})
    if not improvement:
        return []
    final = summary.get("probability_of_improvement_final", {})
    baseline = summary.get("improvement", {}).get("over")
    figure = f"mean return over the {LATE_LABEL}"
    if baseline:
        sentence = f"P(a seed's {figure} > a {display_name(baseline)} seed's)"
        first = f"| method | P(method > {display_name(baseline)}) | 95% CI |"
    else:
        sentence = f"P(a PN-GAIL seed's {figure} > a baseline seed's)"
        first = "| over | P(PN-GAIL > baseline) | 95% CI |"
    lines = [
        "",
        f"Probability of improvement: {sentence}, 95% bootstrap interval; beside it the same "
        "on the final evaluation. An interval holding 0.5 is no ranking: more seeds decide.",
        "",
        first + " final evaluation: P | 95% CI |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, value in improvement.items():
        columns = [display_label(label)]
        for entry in (value, final.get(label)):
            if entry is None:
                columns += ["n/a", "n/a"]
            elif min(entry.get("seeds", (2, 2))) == 1:  # one seed a side: a single comparison
                columns += [f"{entry['estimate']:.2f} (n = 1)", "no interval"]
            else:
                low, high = entry["ci95"]
                holds = " (holds 0.5)" if low <= 0.5 <= high else ""
                columns += [f"{entry['estimate']:.2f}", f"[{low:.2f}, {high:.2f}]{holds}"]
        lines.append("| " + " | ".join(columns) + " |")
    return lines


def display_label(label: str) -> str:
    """A group label (``group_label``) with the method's paper name (``PN-GAIL\\BSC``, not
    ``pngail-no-bsc``), for the tables people read; summary.json keeps the ids."""
    method, bracket, setting = label.partition(" [")
    return display_name(method) + bracket + setting


def _per_seed_lines(summary: dict) -> list[str]:
    """summary.md's per-seed table: each seed's three returns, raw and normalised."""
    lines = [
        "",
        "Per seed:",
        "",
        f"| method | seed | final return | normalised | {LATE_LABEL} | normalised | "
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
            lines.append(f"| {display_label(label)} | {seed['seed']} | {cells_text} |")
    return lines


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
