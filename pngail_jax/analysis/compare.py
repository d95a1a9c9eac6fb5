"""Comparisons across runs and tasks, as rliable defines them (Agarwal et al., 2021).

A score is a seed's normalised return, (R - random) / (optimal - random), read from a
sweep or offline run's ``metrics.csv``, or from a run record (``records/<name>``, checked by
``run_records.check_record``: its per-seed lists); ``PATH:A,B`` takes methods A and B of it
alone. By default the headline figure, its mean over the last
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
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pngail_jax.analysis import run_records, stats
from pngail_jax.analysis.report import HEADLINE
from pngail_jax.analysis.runs import (
    RUN_PROGRAMS,
    STATISTICS,
    RunReadError,
    read_run_config,
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


# What may follow a path's last colon as the methods picked from it: names joined by commas.
PICK = re.compile(r"[\w.+-]+(,[\w.+-]+)*")


@dataclasses.dataclass(frozen=True)
class Source:
    """A run folder or a run record's folder to compare, and the methods picked from it
    (None: every method it has)."""

    path: Path
    methods: tuple[str, ...] | None = None

    def __str__(self) -> str:
        return str(self.path) + ("" if self.methods is None else ":" + ",".join(self.methods))


def parse_source(text: str) -> Source:
    """``PATH`` or ``PATH:A,B`` (methods A and B of it alone). Split at the last colon only
    when what follows reads as method names and what comes before exists, so that a path
    holding a colon stays whole."""
    before, colon, after = text.rpartition(":")
    if colon and before and PICK.fullmatch(after) and Path(before).exists():
        return Source(Path(before), tuple(after.split(",")))
    return Source(Path(text))


def is_record(folder: Path) -> bool:
    """Whether ``folder`` holds a run record (``records/<name>``) rather than a run."""
    return (Path(folder) / run_records.RECORD_FILE).is_file()


def _same_run_key(folder: Path) -> str | None:
    """What makes two runs the same seeds of the same config: config.json (a record's
    ``config``, the same document) without where and how it ran (``provenance``) and the log,
    its trainer's learner in today's layout (a run begun before the trainer's learner part
    holds the same settings in another shape); None when it cannot be read."""
    try:
        if is_record(folder):
            config = read_json(Path(folder) / run_records.RECORD_FILE, "run record")
            config = config.get("config") if isinstance(config, dict) else None
        else:
            config = read_json(Path(folder) / "config.json", "run config")
    except (OSError, IntegrityError):
        return None
    if not isinstance(config, dict):
        return None
    kept = {key: value for key, value in config.items() if key not in ("provenance", "log")}
    resolved = kept.get("resolved")
    if isinstance(resolved, dict) and isinstance(resolved.get("trainer"), dict):
        kept["resolved"] = {**resolved, "trainer": upgrade_trainer_learner(resolved["trainer"])}
    return json.dumps(kept, sort_keys=True)


def _check_distinct(folders: Sequence[Path]) -> None:
    """CompareError when a run or record is given twice, or two of them hold the same seeds
    of the same config (a copy, a record and the run it was made from, or the same command
    run again): pooling them would count each seed twice and shrink every interval."""
    seen_paths: dict[Path, Path] = {}
    seen_configs: dict[str, Path] = {}
    for folder in map(Path, folders):
        resolved = folder.resolve()
        if resolved in seen_paths:
            first = seen_paths[resolved]
            also = "" if str(first) == str(folder) else f" (as {first} too)"
            raise CompareError(
                f"{folder} is given twice{also}: give it once (PATH:A,B picks several of "
                "its methods)"
            )
        seen_paths[resolved] = folder
        key = _same_run_key(folder)
        if key is not None and key in seen_configs:
            raise CompareError(
                f"{folder} and {seen_configs[key]} are the same seeds of the same config "
                "(a copy, a record of the run, or the same command run twice): compare one "
                "of them, or give the sweep another --seed for more seeds"
            )
        if key is not None:
            seen_configs[key] = folder


def _record_scores(folder: Path, statistic: str) -> tuple[str, dict[str, np.ndarray], str | None]:
    """A run record's task, each method's scores float[seeds] under ``statistic`` (NaN for a
    diverged seed), and how far its run got (None when complete). CompareError for a record
    that does not check (``run_records.check_record``) or is of another program's run."""
    _check_record_program(folder)
    try:
        record = run_records.check_record(folder)
    except run_records.RecordError as error:
        raise CompareError(str(error)) from None
    task = read_run_config(record["config"]).settings.get("env")
    if task is None:
        raise CompareError(f"{folder / run_records.RECORD_FILE}: its config names no env")
    per_seed = record[run_records.statistic_key(statistic)]
    scores = {method: run_records.seed_values(seeds) for method, seeds in per_seed.items()}
    done, planned = record.get("iterations_done"), record.get("iterations")
    progress = None if record["complete"] else f"{done:,} of {planned:,} iterations"
    return str(task), scores, progress


def _check_record_program(folder: Path) -> None:
    """CompareError for a record of another program than a sweep or an offline run (a
    settings comparison's, ``experiments.compare_settings``): it holds no method's seeds.
    An unreadable record is left to ``check_record`` to name."""
    try:
        record = read_json(Path(folder) / run_records.RECORD_FILE, "run record")
    except (OSError, IntegrityError):
        return
    program = record.get("program") if isinstance(record, dict) else None
    if isinstance(program, str) and program.removeprefix("experiments.") not in RUN_PROGRAMS:
        raise CompareError(
            f"{folder} is a record of {program}, not of a sweep or an offline run: it holds no "
            "method's seeds to compare"
        )


def _picked(source: Source, scores: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``scores`` of the methods ``source`` picks (all without a pick); CompareError naming
    a picked method it does not have, and those it has."""
    if source.methods is None:
        return scores
    missing = [method for method in source.methods if method not in scores]
    if missing:
        raise CompareError(
            f"{source.path} has no method {missing[0]!r} (it has {', '.join(scores)})"
        )
    return {method: scores[method] for method in source.methods}


def load_scores(
    sources: Sequence[Path | Source], statistic: str = HEADLINE, *, allow_unsealed: bool = False
) -> Scores:
    """The scores (``statistic``) of every run folder or run record (a ``Source`` may pick
    some of its methods), pooled per task (two sources of one task: their seeds together).
    Methods keep the order they first appear in. CompareError for a folder given twice, two of
    the same seeds and config (a record and its run among them), a picked method a source does
    not have, a record that does not check (``run_records.check_record``), or a run that fails
    ``runs.verify_run`` (its seal missing, unless ``allow_unsealed``, or not matching its
    config; a damaged or cut-short metrics.csv; a summary.json that disagrees with it). Input
    files are not checked: a comparison reads results, not data. Notes of what was let
    through are in the returned ``Scores.notes``; unfinished runs and records (read to their
    latest evaluation) in ``Scores.unfinished``."""
    if statistic not in STATISTICS:
        raise CompareError(f"statistic {statistic!r}: give one of {', '.join(STATISTICS)}")
    sources = [item if isinstance(item, Source) else Source(Path(item)) for item in sources]
    _check_distinct([source.path for source in sources])
    values: dict[str, dict[str, np.ndarray]] = {}
    unfinished, notes = {}, []
    for source in sources:
        if is_record(source.path):
            task, scores, progress = _record_scores(source.path, statistic)
        else:
            notes += verify_run(
                source.path, str(source.path), allow_unsealed=allow_unsealed, check_inputs=False
            )
            (task, scores), progress = run_scores(source.path, statistic), run_progress(source.path)
        for method, seeds in _picked(source, scores).items():
            by_task = values.setdefault(method, {})
            by_task[task] = np.concatenate([by_task.get(task, np.empty(0)), seeds])
        if progress is not None:
            unfinished[str(source.path)] = progress
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
