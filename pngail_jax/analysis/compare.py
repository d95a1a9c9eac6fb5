"""Comparisons across runs and tasks, as rliable defines them (Agarwal et al., 2021).

A score is a seed's normalised return, (R - random) / (optimal - random), read from a
sweep run's ``metrics.csv``: by default the headline figure, its mean over the last
``report.LATE_SHARE`` of training (``statistic="late_average"``), or its final evaluation
(``statistic="final"``). ``Scores`` holds them per method (a method label: the method,
plus its setting when a run has several) and task (the run's environment; runs of one task
pool their seeds). Over all tasks, for each method:

- **IQM**: the interquartile mean of every seed-task score pooled;
- **mean** and **median**: of the per-task means of the seeds' scores;
- **optimality gap**: ``gamma - mean(min(score, gamma))`` over the pooled scores (gamma 1:
  how far below the optimal return the method stays, a score above 1 counting as 1);

each with a stratified bootstrap interval (seeds resampled within each task). A
**performance profile** is the fraction of pooled scores above each threshold tau, with the
same bootstrap band. The **probability of improvement** of X over Y is the mean over their
common tasks of P(X's score > Y's) + P(equal) / 2 (the Mann-Whitney statistic per task), its
interval from resampling each method's seeds independently within each task.

Each task is also summarised on its own (every task, including those not every method ran):
each method's mean ± standard error, IQM with its bootstrap interval over the task's seeds,
and the baseline's probability of improvement over it there.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.analysis.report import HEADLINE
from pngail_jax.analysis.runs import (
    STATISTICS,
    RunReadError,
    run_progress,
    run_scores,
    verify_run,
)
from pngail_jax.config.learner import upgrade_trainer_learner
from pngail_jax.storage.integrity import IntegrityError, atomic_path, read_json, write_json

AGGREGATES = ("iqm", "mean", "median", "optimality_gap")
NUM_RESAMPLES = 2000


CompareError = RunReadError  # the name programs catch


@dataclasses.dataclass
class Scores:
    """Normalised scores: ``values[method][task]`` float[seeds], each seed's ``statistic``
    (a key of ``STATISTICS``)."""

    values: dict[str, dict[str, np.ndarray]]
    unfinished: dict[str, str] = dataclasses.field(default_factory=dict)  # run -> how far
    statistic: str = HEADLINE
    notes: list[str] = dataclasses.field(default_factory=list)  # what verify_run let through

    @property
    def methods(self) -> list[str]:
        return list(self.values)

    @property
    def tasks(self) -> list[str]:
        return list(dict.fromkeys(task for by_task in self.values.values() for task in by_task))

    def only(self, methods: Sequence[str]) -> Scores:
        """The scores of ``methods`` alone, in that order (CompareError naming one the runs
        do not have)."""
        if not methods:
            raise CompareError("--methods names no method")
        unknown = [method for method in methods if method not in self.values]
        if unknown:
            raise CompareError(
                f"--methods: {', '.join(unknown)} not in the runs (their methods: "
                f"{', '.join(self.methods)})"
            )
        kept = {method: self.values[method] for method in methods}
        return dataclasses.replace(self, values=kept)

    def common(self) -> tuple[Scores, dict[str, list[str]]]:
        """The scores on the tasks where every method has a finite score (aggregates over
        different task sets would not compare), and the tasks left out per method.
        CompareError if none."""
        shared = [
            t for t in self.tasks
            if all(t in by and np.isfinite(by[t]).any() for by in self.values.values())
        ]  # fmt: skip
        if not shared:
            raise CompareError(f"no task is common to every method: {self.methods}")
        left_out = {
            method: [task for task in by_task if task not in shared]
            for method, by_task in self.values.items()
        }
        kept = {m: {t: by[t] for t in shared} for m, by in self.values.items()}
        left_out = {m: tasks for m, tasks in left_out.items() if tasks}
        # (unfinished: every run read, named)
        return Scores(kept, self.unfinished, self.statistic, self.notes), left_out

    def pooled(self, method: str) -> tuple[np.ndarray, np.ndarray]:
        """float[n] scores and int[n] task labels (index into ``tasks``) of ``method``'s
        finite scores, task by task."""
        tasks = self.tasks
        values, labels = [], []
        for task, scores in self.values[method].items():
            finite = scores[np.isfinite(scores)]
            values.append(finite)
            labels.append(np.full(finite.size, tasks.index(task)))
        return np.concatenate(values), np.concatenate(labels)


def _same_run_key(run_dir: Path) -> str | None:
    """What makes two runs the same seeds of the same config: config.json without where and
    how it ran (``provenance``) and the log, its trainer's learner in today's layout (a run
    begun before the trainer's learner part holds the same settings in another shape); None
    when it cannot be read."""
    try:
        config = read_json(run_dir / "config.json", "run config")
    except (OSError, IntegrityError):
        return None
    if not isinstance(config, dict):
        return None
    kept = {key: value for key, value in config.items() if key not in ("provenance", "log")}
    resolved = kept.get("resolved")
    if isinstance(resolved, dict) and isinstance(resolved.get("trainer"), dict):
        kept["resolved"] = {**resolved, "trainer": upgrade_trainer_learner(resolved["trainer"])}
    return json.dumps(kept, sort_keys=True)


def _check_distinct(run_dirs: Sequence[Path]) -> None:
    """CompareError when a run is given twice, or two runs hold the same seeds of the same
    config (a copy, or the same command run again): pooling them would count each seed
    twice and shrink every interval."""
    seen_paths: dict[Path, Path] = {}
    seen_configs: dict[str, Path] = {}
    for run_dir in map(Path, run_dirs):
        resolved = run_dir.resolve()
        if resolved in seen_paths:
            first = seen_paths[resolved]
            also = "" if str(first) == str(run_dir) else f" (as {first} too)"
            raise CompareError(f"{run_dir} is given twice{also}")
        seen_paths[resolved] = run_dir
        key = _same_run_key(run_dir)
        if key is not None and key in seen_configs:
            raise CompareError(
                f"{run_dir} and {seen_configs[key]} are the same seeds of the same config "
                "(a copy, or the same command run twice): compare one of them, or give the "
                "sweep another --seed for more seeds"
            )
        if key is not None:
            seen_configs[key] = run_dir


def load_scores(
    run_dirs: Sequence[Path], statistic: str = HEADLINE, *, allow_unsealed: bool = False
) -> Scores:
    """The scores (``statistic``) of every run, pooled per task (two runs of one task: their
    seeds together). Methods keep the order they first appear in. CompareError for a run given
    twice, two runs of the same seeds and config, or one that fails ``runs.verify_run`` (its
    seal missing, unless ``allow_unsealed``, or not matching its config; a damaged or
    cut-short metrics.csv; a summary.json that disagrees with it). Input files are not
    checked: a comparison reads results, not data. Notes of what was let through are in the
    returned ``Scores.notes``."""
    _check_distinct(run_dirs)
    values: dict[str, dict[str, np.ndarray]] = {}
    unfinished, notes = {}, []
    for run_dir in run_dirs:
        notes += verify_run(
            Path(run_dir), str(run_dir), allow_unsealed=allow_unsealed, check_inputs=False
        )
        task, scores = run_scores(run_dir, statistic)
        for method, seeds in scores.items():
            by_task = values.setdefault(method, {})
            by_task[task] = np.concatenate([by_task.get(task, np.empty(0)), seeds])
        progress = run_progress(run_dir)
        if progress is not None:
            unfinished[str(run_dir)] = progress
    return Scores(values, unfinished, statistic, notes)


# -- aggregates: statistic(samples float[R, n], labels int[n]) -> float[R] ------------------


def _task_means(samples: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """float[R, T]: the mean score of each task present in ``labels``."""
    return np.stack([samples[:, labels == task].mean(axis=1) for task in np.unique(labels)], axis=1)


def _statistic(name: str):
    def iqm(samples, labels):
        return stats.iqm(samples, axis=-1)

    def mean(samples, labels):
        return _task_means(samples, labels).mean(axis=1)

    def median(samples, labels):
        return np.median(_task_means(samples, labels), axis=1)

    def optimality_gap(samples, labels, gamma=1.0):
        return gamma - np.minimum(samples, gamma).mean(axis=1)

    return {"iqm": iqm, "mean": mean, "median": median, "optimality_gap": optimality_gap}[name]


def _stratified_samples(values, labels, num_resamples, seed):
    """float[R, n] resamples (seeds redrawn within each task) and their int[n] labels."""
    order = np.argsort(labels, kind="stable")
    values, labels = values[order], labels[order]
    rng = np.random.default_rng(seed)
    columns = stats.resample_indices(rng, labels, num_resamples)
    return values[columns], labels


def aggregate(
    scores: Scores, method: str, name: str, *, num_resamples: int = NUM_RESAMPLES, seed: int = 0
) -> dict:
    """``{"estimate", "ci95"}`` of aggregate ``name`` (``AGGREGATES``) for ``method``."""
    values, labels = scores.pooled(method)
    if values.size == 0:
        return {"estimate": math.nan, "ci95": [math.nan, math.nan]}
    statistic = _statistic(name)
    estimate = float(statistic(values[None, :], labels)[0])
    samples, sample_labels = _stratified_samples(values, labels, num_resamples, seed)
    low, high = np.percentile(statistic(samples, sample_labels), [2.5, 97.5])
    return {"estimate": estimate, "ci95": [float(low), float(high)]}


def performance_profile(
    scores: Scores, method: str, taus: np.ndarray, *, num_resamples=NUM_RESAMPLES, seed=0
) -> dict:
    """The fraction of ``method``'s pooled scores above each tau float[K], and its stratified
    bootstrap band: ``{"fraction": [K], "low": [K], "high": [K]}``."""
    values, labels = scores.pooled(method)
    if values.size == 0:
        nan = [math.nan] * len(taus)
        return {"fraction": nan, "low": nan, "high": nan}
    fraction = (values[:, None] > taus[None, :]).mean(axis=0)
    samples, _ = _stratified_samples(values, labels, num_resamples, seed)
    resampled = (samples[:, :, None] > taus[None, None, :]).mean(axis=1)
    low, high = np.percentile(resampled, [2.5, 97.5], axis=0)
    return {"fraction": fraction.tolist(), "low": low.tolist(), "high": high.tolist()}


def probability_of_improvement(
    scores: Scores, x: str, y: str, *, num_resamples: int = NUM_RESAMPLES, seed: int = 0
) -> dict:
    """P(X > Y): the mean over the tasks both have of the per-task probability, with a
    bootstrap interval resampling X's and Y's seeds independently within each task.
    ``{"estimate", "ci95", "tasks"}``; NaN without a common task."""
    tasks = [t for t in scores.values[x] if t in scores.values[y]]
    pairs = [(_finite(scores.values[x][t]), _finite(scores.values[y][t])) for t in tasks]
    pairs = [(a, b) for a, b in pairs if a.size and b.size]
    if not pairs:
        return {"estimate": math.nan, "ci95": [math.nan, math.nan], "tasks": []}
    estimate = float(np.mean([stats.probability_of_improvement(a, b) for a, b in pairs]))
    rng = np.random.default_rng(seed)
    per_task = []
    for a, b in pairs:
        a_samples = a[rng.integers(0, a.size, size=(num_resamples, a.size))]
        b_samples = b[rng.integers(0, b.size, size=(num_resamples, b.size))]
        per_task.append(stats.improvement(a_samples, b_samples))
    low, high = np.percentile(np.mean(per_task, axis=0), [2.5, 97.5])
    return {"estimate": estimate, "ci95": [float(low), float(high)], "tasks": tasks}


def _finite(values: np.ndarray) -> np.ndarray:
    return values[np.isfinite(values)]


def per_task(scores: Scores, baseline: str, *, seed: int = 0) -> dict:
    """Each task's methods on their own: ``{task: {method: {"seeds", "mean", "se", "iqm",
    "baseline_improvement"}}}``, the IQM with its bootstrap interval over the task's seeds and
    ``baseline_improvement`` the baseline's P(baseline > method) there (absent for the
    baseline, and where it did not run the task)."""
    table = {}
    for task in scores.tasks:
        rows = {}
        for method, by_task in scores.values.items():
            if task not in by_task:
                continue
            values = _finite(by_task[task])
            rows[method] = {
                "seeds": int(values.size),
                "mean": float(values.mean()) if values.size else math.nan,
                "se": stats.standard_error(values),
                "iqm": aggregate(Scores({method: {task: values}}), method, "iqm", seed=seed),
            }
            if method != baseline and task in scores.values[baseline]:
                pair = Scores({baseline: {task: scores.values[baseline][task]},
                               method: {task: values}})  # fmt: skip
                rows[method]["baseline_improvement"] = probability_of_improvement(
                    pair, baseline, method, seed=seed
                )
        table[task] = rows
    return table


def compare(scores: Scores, baseline: str, *, seed: int = 0) -> dict:
    """Every aggregate of every method, and each method's probability of improvement over
    ``baseline``: the document ``compare.json`` holds."""
    if baseline not in scores.values:
        raise CompareError(f"baseline {baseline!r} is not among the methods: {scores.methods}")
    tasks = per_task(scores, baseline, seed=seed)  # every task, before those in common
    scores, left_out = scores.common()
    taus = np.linspace(-0.25, 1.25, 61)
    return {
        "statistic": scores.statistic,
        "tasks": scores.tasks,
        "left_out": left_out,
        "seeds": {
            m: {t: int(np.isfinite(v).sum()) for t, v in by.items()}
            for m, by in scores.values.items()
        },  # fmt: skip
        "aggregates": {
            method: {name: aggregate(scores, method, name, seed=seed) for name in AGGREGATES}
            for method in scores.methods
        },
        "baseline": baseline,
        "probability_of_improvement": {
            method: probability_of_improvement(scores, method, baseline, seed=seed)
            for method in scores.methods
            if method != baseline
        },
        "profiles": {
            "taus": taus.tolist(),
            **{m: performance_profile(scores, m, taus, seed=seed) for m in scores.methods},
        },
        "per_task": tasks,
        "unfinished": scores.unfinished,
        "notes": scores.notes,
    }


def markdown(result: dict) -> str:
    """compare.md: the aggregates and the probabilities of improvement as tables."""
    tasks = ", ".join(result["tasks"])
    lines = [
        f"# Comparison over {len(result['tasks'])} task(s): {tasks}",
        "",
        f"Score: {_score_text(result).capitalize()}; 95% stratified bootstrap intervals "
        "(seeds resampled within each task). Optimality gap: lower is better.",
        "",
        *(
            [f"Left out (not every method ran them): {result['left_out']}.", ""]
            if result["left_out"]
            else []
        ),
        *(
            [
                "**Unfinished runs**, read up to their latest evaluation so far: "
                + "; ".join(f"{run} ({how})" for run, how in result["unfinished"].items())
                + ".",
                "",
            ]
            if result.get("unfinished")
            else []
        ),
        *(
            [f"**Checks let through**: {'; '.join(result['notes'])}.", ""]
            if result.get("notes")
            else []
        ),  # fmt: skip
        "| method | seeds | IQM | mean | median | optimality gap |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for method, values in result["aggregates"].items():
        seeds = sum(result["seeds"][method].values())
        cells = [_estimate(values[n]) for n in AGGREGATES]
        lines.append(f"| {method} | {seeds} | " + " | ".join(cells) + " |")
    baseline = result["baseline"]
    lines += ["", f"| method | P(method > {baseline}) | 95% CI | tasks |", "|---|---:|---:|---:|"]
    for method, value in result["probability_of_improvement"].items():
        low, high = value["ci95"]
        lines.append(
            f"| {method} | {value['estimate']:.2f} | [{low:.2f}, {high:.2f}] | "
            f"{len(value['tasks'])} |"
        )
    lines += per_task_markdown(result["per_task"], baseline)
    return "\n".join(lines) + "\n"


def _score_text(result: dict) -> str:
    """What a score of ``result`` is (older compare.json files hold final returns)."""
    return STATISTICS[result.get("statistic", "final")]


def _estimate(value: dict) -> str:
    low, high = value["ci95"]
    return f"{value['estimate']:.2f} [{low:.2f}, {high:.2f}]"


def per_task_markdown(table: dict, baseline: str) -> list[str]:
    """One table per task: each method's score (mean ± s.e., IQM with its 95% bootstrap
    interval) and the baseline's probability of improvement over it."""
    lines = ["", "## Per task", ""]
    for task, rows in table.items():
        lines += [
            f"**{task}**",
            "",
            f"| method | seeds | mean ± s.e. | IQM [95% CI] | P({baseline} > method) [95% CI] |",
            "|---|---:|---:|---:|---:|",
        ]
        for method, row in rows.items():
            improvement = row.get("baseline_improvement")
            spread = f" ± {row['se']:.2f}" if row["seeds"] > 1 else " (n = 1)"
            lines.append(
                f"| {method} | {row['seeds']} | {row['mean']:.2f}{spread} | "
                f"{_estimate(row['iqm'])} | {_estimate(improvement) if improvement else '-'} |"
            )
        lines.append("")
    return lines


def write_result_json(path: Path, result: dict) -> None:
    """``result`` as JSON, an undefined number (NaN) as null."""

    def nulls(value):
        if isinstance(value, dict):
            return {key: nulls(item) for key, item in value.items()}
        if isinstance(value, list | tuple):
            return [nulls(item) for item in value]
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    write_json(path, nulls(result))


def _interval_rows(axis, rows, colors) -> None:
    """Horizontal bars from each row's interval, a tick at its estimate: rows are
    ``(label, {"estimate", "ci95"})``."""
    for row, (label, value) in enumerate(rows):
        low, high = value["ci95"]
        axis.barh(row, high - low, left=low, height=0.6, color=colors[label], alpha=0.7)
        axis.plot([value["estimate"]] * 2, [row - 0.3, row + 0.3], color="black", lw=1.5)
    axis.set(yticks=range(len(rows)))
    axis.invert_yaxis()


def plot(result: dict, directory: Path) -> list[Path]:
    """aggregates.png (each aggregate's estimate and interval per method), profiles.png
    (performance profiles with their bands) and improvement.png (P(method > baseline))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(result["aggregates"])
    colors = {m: plt.cm.tab10(i % 10) for i, m in enumerate(methods)}
    written = []

    def save(figure, name):
        figure.tight_layout()
        with atomic_path(directory / name) as temporary:
            figure.savefig(temporary, dpi=120)
        plt.close(figure)
        written.append(directory / name)

    height = 1.2 + 0.35 * len(methods)
    figure, axes = plt.subplots(1, len(AGGREGATES), figsize=(3.2 * len(AGGREGATES), height))
    for axis, name in zip(axes, AGGREGATES, strict=True):
        _interval_rows(axis, [(m, result["aggregates"][m][name]) for m in methods], colors)
        axis.set_title(name.replace("_", " "))
        axis.set_yticklabels(methods if axis is axes[0] else [])
        axis.grid(axis="x", alpha=0.3)
    figure.supxlabel(f"{_score_text(result)} (95% stratified bootstrap interval)")
    save(figure, "aggregates.png")

    figure, axis = plt.subplots(figsize=(7, 4.5))
    taus = np.asarray(result["profiles"]["taus"])
    for method in methods:
        profile = result["profiles"][method]
        axis.plot(taus, profile["fraction"], color=colors[method], label=method)
        axis.fill_between(taus, profile["low"], profile["high"], color=colors[method], alpha=0.2)
    axis.set(xlabel="normalised return tau", ylabel="fraction of runs with score > tau",
             title="performance profiles")  # fmt: skip
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8)
    save(figure, "profiles.png")

    improvements = result["probability_of_improvement"]
    figure, axis = plt.subplots(figsize=(7, 1.2 + 0.35 * max(len(improvements), 1)))
    _interval_rows(axis, list(improvements.items()), colors)
    axis.axvline(0.5, color="gray", ls="--", lw=1)
    axis.set(xlim=(0, 1), xlabel=f"P(method > {result['baseline']}) (95% interval)")
    axis.set_yticklabels(list(improvements))
    save(figure, "improvement.png")
    return written
