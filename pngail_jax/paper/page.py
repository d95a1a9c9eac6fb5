"""The results page of a plan: every figure's plot and table beside the paper's numbers,
``results.json``, and notes on what a budget can say."""

from __future__ import annotations

import dataclasses
import math
import types
from pathlib import Path

import numpy as np

from pngail_jax import envs
from pngail_jax.adversarial.methods import display_name
from pngail_jax.analysis.plots import line_style
from pngail_jax.analysis.report import LATE_LABEL, group_label, late_evaluations
from pngail_jax.analysis.runs import read_run_config
from pngail_jax.config.budget import CHECK_PHASE_SIZES
from pngail_jax.paper.plan import (
    BUDGETS,
    PAPER_TABLE1,
    PAPER_TABLE4,
    PAPER_TABLE4_OPTIMAL,
    Figure,
    Series,
)  # fmt: skip
from pngail_jax.storage.integrity import atomic_write_text, read_json, write_json

# -- the results page ------------------------------------------------------------------------


def read_grid_curves(directory: Path) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """(method, setting) -> {"steps": int[T], "normalized": float[seeds, T]} from a grid's
    metrics.csv, evaluated iterations only (``report.read_evaluations``)."""
    from pngail_jax.analysis.report import read_evaluations

    evaluations = read_evaluations(
        directory / "metrics.csv",
        "normalized_return",
        evaluated_by="eval_return",
        group_by=("method", "setting"),
    )
    return {
        key: {"steps": steps, "normalized": values} for key, (steps, values) in evaluations.items()
    }


def series_statistics(series: Series, curves, summary) -> dict:
    """Final and training-averaged normalised return (mean, std, standard error, 95% bootstrap
    interval of the mean) of a series, and its classifier error."""
    from pngail_jax.analysis import stats

    matches = [key for key in curves if key[0] == series.method]
    if series.setting is not None:
        matches = [key for key in matches if key[1] == series.setting]
    if len(matches) != 1:
        raise ValueError(f"{series.grid}: expected one curve of {series}, found {matches}")
    curve = curves[matches[0]]
    values = curve["normalized"]
    result = {"steps": curve["steps"].tolist(), "curve": values.tolist()}
    late = values[:, values.shape[1] - late_evaluations(values.shape[1]) :]
    averages = (("average", np.nanmean(values, axis=1)), ("late", np.nanmean(late, axis=1)))
    for name, per_seed in (("final", values[:, -1]), *averages):
        summary_of = stats.seed_summary(per_seed)
        low, high = stats.bootstrap_ci(per_seed, np.mean)
        result[name] = {
            "mean": summary_of["mean"],
            "std": summary_of["std"],
            "se": summary_of["se"],
            "ci95": [low, high],
            "seeds": summary_of["num_seeds"],
        }
    settings = list(dict.fromkeys(setting for _, setting in curves))
    cell = types.SimpleNamespace(method=series.method, setting=matches[0][1])
    row = summary["methods"].get(group_label(cell, settings), {})  # summary.json's key
    for name in ("average_return", "late_average_return"):
        result[name] = [row.get(f"{name}_mean"), row.get(f"{name}_se")]
    for name in ("mae", "rmse"):
        result[f"confidence_{name}"] = [
            row.get(f"confidence_{name}_mean"),
            row.get(f"confidence_{name}_std"),
        ]
    return result


def _number(value, digits: int = 2) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _mean_se(entry: dict) -> str:
    """mean ± standard error over seeds (the one spread convention of every table)."""
    if entry["seeds"] == 1:
        return f"{_number(entry['mean'])} (n = 1)"
    return f"{_number(entry['mean'])} ± {_number(entry['se'])}"


def series_name(series: Series) -> str:
    """A series' name in legends and tables: the paper's name of its method."""
    return display_name(series.method) if series.label == series.method else series.label


def _interval(entry: dict) -> str:
    low, high = entry["ci95"]
    return f"[{_number(low)}, {_number(high)}]"


def plot_figure(path: Path, figure: Figure, results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(figure.panels)
    columns = min(3, len(tasks))
    rows = math.ceil(len(tasks) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(5 * columns, 3.6 * rows), squeeze=False)
    for axis in axes.flat[len(tasks) :]:
        axis.set_visible(False)
    for axis, task in zip(axes.flat, tasks, strict=False):
        for series in figure.panels[task]:
            entry = results[task][series.label]
            steps = np.array(entry["steps"]) / 1e6
            curve = np.array(entry["curve"], dtype=float)
            mean = np.nanmean(curve, axis=0)
            spread = (
                np.nanstd(curve, axis=0, ddof=1) / math.sqrt(len(curve)) if len(curve) > 1 else 0
            )
            (line,) = axis.plot(
                steps, mean, label=series_name(series), linewidth=1.5, ls=line_style(series.method)
            )
            axis.fill_between(
                steps, mean - spread, mean + spread, alpha=0.12, color=line.get_color(), lw=0
            )
        axis.axhline(1.0, color="grey", linestyle=":", linewidth=1)
        axis.set_title(task)
        axis.set_xlabel("M environment steps per run")
        axis.set_ylabel("normalised return")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.suptitle(f"{figure.title} (mean ± s.e. over seeds)", fontsize=10)
    fig.tight_layout()
    fig.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.0, 0.95), fontsize=8)
    fig.savefig(path, dpi=110, bbox_inches="tight")  # the legend is outside the panels
    plt.close(fig)


def figure_markdown(figure: Figure, results: dict, command: str) -> list[str]:
    lines = [f"## {figure.title}", "", f"The paper: {figure.paper}.", "", f"    {command}", ""]
    if figure.name == "table1":
        lines += [
            "| task | SC MAE | SC MAE, paper | BSC MAE | BSC MAE, paper | SC RMSE | "
            "SC RMSE, paper | BSC RMSE | BSC RMSE, paper |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for task in figure.panels:
            sc, bsc = results[task]["pngail-no-bsc"], results[task]["pngail"]
            paper = PAPER_TABLE1.get(envs.task_family(task), (None,) * 4)
            lines.append(
                f"| {task} | {_number(sc['confidence_mae'][0], 3)} | {_number(paper[0], 3)} | "
                f"{_number(bsc['confidence_mae'][0], 3)} | {_number(paper[2], 3)} | "
                f"{_number(sc['confidence_rmse'][0], 3)} | {_number(paper[1], 3)} | "
                f"{_number(bsc['confidence_rmse'][0], 3)} | {_number(paper[3], 3)} |"
            )
        return [*lines, ""]
    if figure.name == "table4":
        return [*lines, *table4_markdown(figure, results), ""]
    lines += [
        f"![{figure.name}]({figure.name}.png)",
        "",
        f"| task | series | {LATE_LABEL}: mean ± s.e. | {LATE_LABEL}: 95% CI | final: "
        "mean ± s.e. | final: 95% CI | average over all of training: mean ± s.e. | seeds |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for task, series_list in figure.panels.items():
        for series in series_list:
            entry = results[task][series.label]
            lines.append(
                f"| {task} | {series_name(series)} | {_mean_se(entry['late'])} | "
                f"{_interval(entry['late'])} | {_mean_se(entry['final'])} | "
                f"{_interval(entry['final'])} | {_mean_se(entry['average'])} | "
                f"{entry['final']['seeds']} |"
            )
    return [*lines, ""]


def table4_markdown(figure: Figure, results: dict) -> list[str]:
    """Raw returns, ours under both averages (the last ``LATE_SHARE`` of training, and all of it)
    beside the paper's "average reward after training convergence", per method and task."""
    tasks = list(figure.panels)
    paper_column = {task: {"Pendulum-v1": 0, "Ant": 1}[envs.task_family(task)] for task in tasks}
    header = (
        "| method | "
        + " | ".join(
            f"{task}: ours, {LATE_LABEL} | {task}: ours, all of training | {task}: paper (± std)"
            for task in tasks
        )
        + " |"
    )
    lines = [header, "|---|" + "---:|---:|---:|" * len(tasks)]

    def cell(pair) -> str:
        mean, std = pair
        return f"{_number(mean, 1)} ± {_number(std, 1)}"

    for series in figure.panels[tasks[0]]:
        row = [series_name(series)]
        for task in tasks:
            paper = PAPER_TABLE4.get(series.method)
            row += [
                cell(results[task][series.label]["late_average_return"]),
                cell(results[task][series.label]["average_return"]),
                cell(paper[paper_column[task]]) if paper else "not in the paper",
            ]
        lines.append("| " + " | ".join(row) + " |")
    optimal = ["optimal policy"]
    for task in tasks:
        return_range = results[task].get("return_range")
        ours = _number(return_range[1], 1) if return_range else "n/a"
        optimal += [ours, ours, _number(PAPER_TABLE4_OPTIMAL[paper_column[task]], 2)]
    lines.append("| " + " | ".join(optimal) + " |")
    return lines


def made_sets(out: Path, grids):
    """``(task, metadata)`` of every made demonstration set the plan has made so far."""
    from pngail_jax.demos import DemonstrationError, load_npz

    for task in dict.fromkeys(g.task for g in grids.values() if g.demos.ratio is not None):
        try:
            yield task, load_npz(out / "demos" / task / "demos.npz").metadata
        except (DemonstrationError, FileNotFoundError):
            continue


def weak_expert_notes(out: Path, grids) -> list[str]:
    """One warning line per made demonstration set whose best policy did not beat the random
    one (tiny budgets): its normalised returns run backwards and its confidences mean
    little, which the page must say, not only make_demos' terminal."""
    return [
        f"**Warning: {task}'s made expert ({metadata['optimal_return']:.1f}) does not "
        f"beat the random policy ({metadata['random_return']:.1f}).** Its normalised "
        "returns run backwards and its confidences mean little: a larger preset trains "
        "the expert longer."
        for task, metadata in made_sets(out, grids)
        if not metadata.get("optimal_beats_random", True)
    ]


def made_expert_notes(out: Path, grids) -> list[str]:
    """One line per made demonstration set: its measured random and optimal returns (the
    return range of its task's figures) beside the paper's Table 3 returns of that task."""
    from pngail_jax.config.released_files import PAPER_RETURN_RANGES

    paper = {name.rsplit("-v", 1)[0]: returns for name, returns in PAPER_RETURN_RANGES.items()}
    notes = []
    for task, metadata in made_sets(out, grids):
        random, optimal = paper.get(task.rsplit("-v", 1)[0], (None, None))  # Ant-v4 -> Ant
        table3 = (
            f" (the paper's Table 3: {random:,.1f} and {optimal:,.1f}, so the made expert is at "
            f"{(metadata['optimal_return'] - random) / (optimal - random):.2f} of the paper's "
            "normalised scale)"
            if optimal is not None
            else ""
        )
        notes.append(
            f"{task}'s made demonstrations: random policy {metadata['random_return']:,.1f}, "
            f"expert {metadata['optimal_return']:,.1f}{table3}; {task}'s normalised returns "
            "use these two measured returns."
        )
    return notes


def figure_results(out: Path, figures: list[Figure], grids) -> dict:
    """``{figure: {task: {series label: statistics, "return_range": [random, optimal]}}}`` from
    the grids' curves and summaries under ``out/grids``."""
    shown = {s.grid for figure in figures for series in figure.panels.values() for s in series}
    loaded = {
        name: (
            read_grid_curves(out / "grids" / name),
            read_json(out / "grids" / name / "summary.json"),
        )
        for name in grids
        if name in shown
    }
    results = {}
    for figure in figures:
        results[figure.name] = {
            task: {
                series.label: series_statistics(series, *loaded[series.grid])
                for series in series_list
            }
            for task, series_list in figure.panels.items()
        }
        for task, series_list in figure.panels.items():  # the grid's random / optimal returns
            config = read_json(out / "grids" / series_list[0].grid / "config.json")
            results[figure.name][task]["return_range"] = read_run_config(config).return_range
    return results


def learner_line(options: dict) -> str:
    """The page's sentence on the policy learners: the grids', and the made experts' where
    they differ (``--demo-learner``)."""
    names = {"ppo": "PPO (not the paper's; docs/ppo.md)", "trpo": "TRPO, as the paper"}
    learner = options.get("learner", "trpo")
    line = f"Policy learner: {names[learner]}."
    demo_learner = options.get("demo_learner", learner)
    if demo_learner != learner:
        line += f" The made demonstrations' experts were trained by {demo_learner.upper()}."
    return line


def write_page(
    out: Path,
    options: dict,
    figures: list[Figure],
    grids,
    timings: dict,
    adopted=None,
    *,
    source: Path | None = None,
    progress: dict | None = None,
) -> Path:
    """``README.md``, one plot per figure and ``results.json`` in ``out`` from the outputs of
    the grids in ``source/grids`` (default ``out``'s); ``adopted``: the grids copied from
    finished sweeps (``paper.adopt``), named as such; ``progress``: ``{grid: (iterations
    done, planned) or None}`` of the grids not finished (None: not started), whose panels a
    page so far leaves out (not started) or shows at the iteration reached, saying so."""
    from pngail_jax.analysis.report import json_safe

    adopted, progress = adopted or {}, progress or {}
    source = out if source is None else source
    shown = shown_panels(figures, progress)
    results = figure_results(source, shown, grids)
    budget = options["budget"]
    lines = [
        *page_header(options),
        *grid_table(out, source, grids, timings, adopted, progress),
        "", *made_expert_notes(source, grids), "", *weak_expert_notes(source, grids), "",
    ]  # fmt: skip
    if progress:
        lines += [
            "**A page so far: the plan is not finished.** A grid in progress is shown at the "
            "iteration it reached (its 'final' is its latest evaluation); a task whose grid has "
            "not started is left out of its figures.",
            "",
        ]
    base = f"python -m experiments.paper --preset {budget}"
    if options.get("released_demos"):
        base += f" --released-demos {options['released_demos']}"
    for planned, figure in zip(figures, shown, strict=True):
        command = f"{base} --only {figure.name} --envs {','.join(planned.panels)}"
        if not figure.panels:
            lines += [f"## {figure.title}", "", "No task of this figure has run yet.", ""]
            continue
        lines += figure_markdown(figure, results[figure.name], command)
        lines[-1:-1] = unfinished_notes(planned, progress)
        if figure.name not in ("table1", "table4"):
            plot_figure(out / f"{figure.name}.png", figure, results[figure.name])
    document = {"options": options, "timings": timings, "adopted": adopted, **results}
    if progress:  # a page so far: the grids not finished, and how far each got
        document["unfinished"] = {name: progress_words(state) for name, state in progress.items()}
    write_json(out / "results.json", json_safe(document))
    page = out / "README.md"
    atomic_write_text(page, "\n".join(lines))
    return page


def phase_sizes_note(phase_sizes: str) -> str:
    """What the page says of the appendix baselines' phases at their small check sizes."""
    if phase_sizes != "check":
        return ""
    sizes = CHECK_PHASE_SIZES
    return (
        " The appendix baselines' training phases run at small check sizes, not their "
        f"codebases': T-REX's and each D-REX reward fit {sizes['ranking_steps']:,} steps of "
        f"{sizes['ranking_pairs_per_step']} pairs, "
        f"D-REX's cloning {sizes['drex_bc_steps']:,} steps and "
        f"{sizes['drex_rollouts_per_level']} noisy episode(s) per level, CAIL "
        f"{sizes['cail_rounds']} rounds per iteration, f-IRL "
        f"{sizes['firl_discriminator_iterations']} discriminator steps per iteration."
    )


def page_header(options: dict) -> list[str]:
    """The page's title, what its numbers mean, and the command that made it."""
    budget = options["budget"]
    return [
        f"# The paper's figures at the {budget} preset",
        "",
        f"Preset `{budget}`: {BUDGETS[budget].iterations:,} iterations, {BUDGETS[budget].seeds} "
        "seeds per method. Normalised return: (R - R_random) / (R_optimal - R_random), with "
        "the paper's Table 3 returns for the authors' files and each made set's own measured "
        f"random and optimal returns. The {LATE_LABEL} (the headline, first): the mean of a "
        "seed's evaluations in that share of training, the figure two re-runs agree on best "
        "(and our reading of the paper's Table 4 'average reward after training "
        "convergence'); 'final' is the last evaluation; 'average over all "
        "of training' the mean of every evaluation; mean ± standard error over seeds and a "
        "95% percentile-bootstrap interval of the mean (the paper's own Table 4 numbers are "
        "± its std). "
        + ("**The check preset checks that everything runs; its numbers are not results.**"
           if budget in ("check", "test") else "")
        + phase_sizes_note(BUDGETS[budget].phase_sizes),
        "",
        f"Made with `{options['command']}`. {learner_line(options)}",
        "",
    ]  # fmt: skip


def grid_table(out: Path, source: Path, grids, timings: dict, adopted: dict, progress: dict):
    """The table of the plan's grids: task, demonstrations, methods and wall time (or adopted
    from where, or how far a grid not finished got), each linked to its summary from ``out``."""
    import os

    lines = [
        "| grid | task | demonstrations | methods | wall time |",
        "|---|---|---|---|---:|",
    ]
    for name, grid in grids.items():
        seconds = timings.get(name)
        wall = "n/a" if seconds is None else f"{seconds / 60:.1f} min"
        if name in adopted:
            commit = (adopted[name].get("commit") or "unknown")[:7]
            wall = f"adopted from `{adopted[name]['from']}` (commit {commit})"
        if name in progress:
            wall = progress_words(progress[name])
        link = Path(os.path.relpath(source / "grids" / name, out)).as_posix()
        named = name if progress.get(name, ()) is None else f"[{name}]({link}/summary.md)"
        lines.append(
            f"| {named} | {grid.task} | {grid.demos.description} | "
            f"{', '.join(grid.methods)} | {wall} |"
        )
    return lines


def progress_words(progress) -> str:
    """A grid's state on a page so far: not started, or the iterations it reached."""
    if progress is None:
        return "not started"
    done, planned = progress
    return f"in progress: {done:,} of {planned:,} iterations"


def shown_panels(figures: list[Figure], progress: dict) -> list[Figure]:
    """Each figure with the panels whose grids have outputs: a task with a grid not started
    (``progress`` None) is left out."""
    return [
        dataclasses.replace(
            figure,
            panels={
                task: series
                for task, series in figure.panels.items()
                if all(progress.get(s.grid, ()) is not None for s in series)
            },
        )
        for figure in figures
    ]


def unfinished_notes(figure: Figure, progress: dict) -> list[str]:
    """Lines under a figure of a page so far: its tasks at fewer iterations, and not run."""
    notes = []
    for task, series in figure.panels.items():
        states = {s.grid: progress[s.grid] for s in series if s.grid in progress}
        for grid, state in states.items():
            if state is None:
                notes.append(f"Not in this figure yet: {task} ({grid} has not started).")
            else:
                notes.append(f"{task} is unfinished: {grid} {progress_words(state)}.")
    return ["", *dict.fromkeys(notes)] if notes else []  # a blank line ends the table
