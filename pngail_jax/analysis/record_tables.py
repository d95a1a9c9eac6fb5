"""The docs' tables made from run records (``run_records.check_record``'s dictionaries and
their folders): a record's headline table, several records at a glance, a run's learning
and its diagnostics per block of environment steps, and its seeds side by side. Each is
the text between a marker of ``experiments.record --docs`` (``programs/record.py``), and
tests/test_docs_tables.py keeps the docs equal to them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.analysis.report import LATE_LABEL, display_label, metrics_rows, read_evaluations
from pngail_jax.analysis.run_records import (
    METRICS_FILE,
    RecordError,
    read_run_config,
    seed_values,
    statistic_key,
)
from pngail_jax.config.presets import DISPLAY_NAMES, display_name, reads_confidences


def record_table(record: dict, baseline: str | None = None) -> str:
    """A results table made from a checked record (``check_record``'s dictionary): per
    method, the headline (the normalised return over the last ``late_share`` of training)
    and the final evaluation, each as mean ± s.e. and IQM [95% bootstrap CI] over seeds, and
    under both the probability of improvement (an interval holding 0.5 says so): PN-GAIL's
    over each method when the record has PN-GAIL, or with ``baseline`` each method's over it.
    The docs' tables between ``<!-- record-table NAME [baseline=METHOD] -->`` markers are
    this text, and a test keeps them so (``experiments.record --docs`` rewrites them)."""

    late, final = record[statistic_key("late_average")], record[statistic_key("final")]
    share = f"last {record['late_share']:.0%} of training"
    anchor = baseline or "pngail"
    if baseline is not None and baseline not in late:
        raise RecordError(f"record {record['name']} has no method {baseline!r}: {list(late)}")

    def summary(seeds) -> tuple[str, str]:
        row = stats.seed_summary(seed_values(seeds))
        low, high = row["ci95"]
        return f"{row['mean']:.2f} ± {row['se']:.2f}", f"{row['iqm']:.2f} [{low:.2f}, {high:.2f}]"

    def improvement(statistic, method) -> str:
        ours, theirs = seed_values(statistic[anchor]), seed_values(statistic[method])
        if baseline is not None:
            ours, theirs = theirs, ours
        low, high = stats.probability_of_improvement_ci(ours, theirs)
        holds = ", holds 0.5" if low <= 0.5 <= high else ""
        return (
            f"{stats.probability_of_improvement(ours, theirs):.2f} [{low:.2f}, {high:.2f}]{holds}"
        )

    compared = anchor in late
    pair = f"method > {display_name(baseline)}" if baseline else f"{display_name(anchor)} > method"
    lines = [
        f"| method | seeds | {share}: mean ± s.e. | {share}: IQM [95% CI] | final: mean ± s.e. "
        "| final: IQM [95% CI] |" + (f" P({pair}), {share} | P, final |" if compared else ""),
        "|---|---:|---:|---:|---:|---:|" + ("---:|---:|" if compared else ""),
    ]
    for method in late:
        seeds = int(np.isfinite(seed_values(late[method])).sum())
        cells = [display_name(method), str(seeds), *summary(late[method]), *summary(final[method])]
        if compared:
            cells += (
                ["-", "-"]
                if method == anchor
                else [improvement(late, method), improvement(final, method)]
            )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def glance_table(
    records: list[dict], statistic: str = "late_average", picks: dict | None = None
) -> str:
    """Several checked records in one table: a row per task (the records of one task
    joined, each method from one record only), a column per method in the paper's order, each
    cell the mean ± s.e. over seeds of ``statistic``'s normalised return ("-": not run).
    ``picks``: ``{record name: [method, ...]}``, only those methods of that record (a default
    measured in a record of its own beside the others'). The docs' tables between ``<!--
    record-glance NAME[:A,B] NAME ... -->`` markers are this text (``experiments.record
    --docs``)."""

    rows: dict[str, dict[str, np.ndarray]] = {}
    for record in records:
        env = str(read_run_config(record["config"]).settings.get("env"))
        task = rows.setdefault(env, {})
        for method, seeds in _picked(record, statistic_key(statistic), picks).items():
            if method in task:
                raise RecordError(
                    f"record {record['name']}: {method!r} on {env} is in another record of "
                    "the table too"
                )
            task[method] = seed_values(seeds)
    # Columns in the paper's order of methods (DISPLAY_NAMES), whichever record each came
    # from; others after them, in the order met.
    met = list(dict.fromkeys(method for task in rows.values() for method in task))
    rank = {name: index for index, name in enumerate(DISPLAY_NAMES)}
    methods = sorted(met, key=lambda method: (rank.get(method, len(rank)), met.index(method)))
    lines = [
        "| task (seeds) | " + " | ".join(display_name(method) for method in methods) + " |",
        "|---|" + "---:|" * len(methods),
    ]
    for env, task in rows.items():
        counts = sorted({int(np.isfinite(seeds).sum()) for seeds in task.values()})
        cells = []
        for method in methods:
            row = stats.seed_summary(task[method]) if method in task else None
            cells.append("-" if row is None else f"{row['mean']:.2f} ± {row['se']:.2f}")
        seeds = "/".join(map(str, counts))
        lines.append(f"| {env} ({seeds}) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _picked(record: dict, key: str, picks: dict | None) -> dict:
    """``record[key]`` (per method), only the methods ``picks`` names for the record when it
    names any; RecordError for a picked method the record does not have."""
    wanted = (picks or {}).get(record["name"])
    if wanted is None:
        return record[key]
    missing = [method for method in wanted if method not in record[key]]
    if missing:
        raise RecordError(
            f"record {record['name']} has no method {missing[0]!r} (it has "
            f"{', '.join(record[key])})"
        )
    return {method: record[key][method] for method in wanted}


def _mean_se(values: np.ndarray) -> str:
    """ "mean ± s.e." of ``values`` (s.e. with ddof 1; "-" for none)."""
    if values.size == 0:
        return "-"
    se = values.std(ddof=1) / math.sqrt(values.size) if values.size > 1 else math.nan
    return f"{values.mean():.2f} ± {se:.2f}"


def _block_label(block: int, block_steps: int, last_step: int, scale: float = 1e6) -> str:
    """A block's span in steps / ``scale`` (M steps, or k gradient steps), its end at most
    the run's last step."""
    low, high = block * block_steps, min((block + 1) * block_steps, last_step)
    return f"{low / scale:g}-{high / scale:g}"


def _step_axis(record: dict) -> tuple[int | None, float, str]:
    """How a record's blocks count: (None, 1e6, "M steps") for a sweep's environment steps;
    an offline run's gradient steps, in thousands: (its gradient steps per iteration, 1e3,
    "k gradient steps")."""
    config = record.get("config")
    view = read_run_config(config) if isinstance(config, dict) else None
    if view is not None and view.program == "offline":
        per_iteration = view.settings.get("steps_per_iteration")
        if not isinstance(per_iteration, int) or per_iteration < 1:
            raise RecordError(f"record {record['name']}: no steps_per_iteration to count in")
        return per_iteration, 1e3, "k gradient steps"
    return None, 1e6, "M steps"


def _blocks_of(record: dict, steps, block_steps: int) -> np.ndarray:
    """The block of each step count (step s in block ceil(s / block_steps) - 1); RecordError
    for a block of no steps or no steps to cut (an offline run's environment steps)."""
    steps = np.asarray(steps)
    if block_steps < 1:
        raise RecordError(f"record {record['name']}: a block of {block_steps} steps")
    if steps.size == 0 or steps.max() < 1:
        raise RecordError(f"record {record['name']}: no environment steps to cut into blocks")
    return (steps - 1) // block_steps


def block_table(record: dict, folder: Path, block_steps: int) -> str:
    """How a recorded run learned, per block of ``block_steps`` environment steps per run
    (an offline run's: gradient steps): per method, each seed's mean normalised evaluation in
    the block (an evaluation at step s is in block ceil(s / block_steps)), then mean ± s.e.
    over seeds; the last column the final evaluation. A seed without a final evaluation
    (diverged) is left out of every column, as from the record's headline. ``folder`` holds
    the checked ``record``. The docs' tables between ``<!-- record-blocks NAME block=STEPS
    -->`` markers are this text."""
    per_iteration, scale, unit = _step_axis(record)
    groups = read_evaluations(
        Path(folder) / METRICS_FILE, "normalized_return", evaluated_by="eval_return",
        group_by=("method", "setting"), steps_per_iteration=per_iteration,
    )  # fmt: skip
    if not groups:
        raise RecordError(f"record {record['name']}: no evaluated iteration")
    settings = {setting for _, setting in groups}
    last = max(int(steps[-1]) for steps, _ in groups.values())
    order = sorted(
        {int(b) for steps, _ in groups.values() for b in _blocks_of(record, steps, block_steps)}
    )
    lines = [
        f"| {unit} | "
        + " | ".join(_block_label(b, block_steps, last, scale) for b in order)
        + f" | final ({last / scale:g} {unit.split()[0]}) |",
        "|---|" + "---:|" * (len(order) + 1),
    ]
    for (method, setting), (steps, values) in groups.items():
        name = display_name(method) + ("" if len(settings) == 1 else f" [{setting}]")
        values = values[np.isfinite(values[:, -1])] if int(steps[-1]) == last else values[:0]
        blocks = _blocks_of(record, steps, block_steps)
        with np.errstate(all="ignore"):
            cells = [_mean_se(np.nanmean(values[:, blocks == b], axis=1)) if (blocks == b).any()
                     else "-" for b in order]  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {_mean_se(values[:, -1])} |")
    return "\n".join(lines) + "\n"


def _check_methods(record: dict, known, methods: list[str] | None) -> None:
    """RecordError naming the first of ``methods`` that is not among ``known``."""
    known = list(dict.fromkeys(known))
    unknown = sorted(set(methods or ()) - set(known))
    if unknown:
        raise RecordError(f"record {record['name']} has no method {unknown[0]!r}: {known}")


# A recorded run's diagnostics columns as ``diagnostics_table`` names them.
DIAGNOSTICS = {
    "disc_acc_agent": ("D accuracy on agent rows", "{:.3f}"),
    "disc_acc_demo": ("D accuracy on demonstration rows", "{:.2f}"),
    "mean_reward": ("mean reward", "{:.3f}"),
    "train_return": ("training return", "{:,.0f}"),
    "beyond_bounds": ("action entries beyond the bounds", "{:.2f}"),
}


def diagnostics_table(
    record: dict, folder: Path, block_steps: int, methods: list[str] | None = None
) -> str:
    """The discriminator and policy diagnostics of a recorded run per block of
    ``block_steps`` environment steps per run: a row per method (``methods``, default all;
    per setting where the run has several) and column of ``DIAGNOSTICS``, each cell the mean
    over every (iteration, seed) row of the block, all seeds pooled: of a record of the
    evaluated rows (``run_records.ROWS``), over those, which the header says. The docs'
    tables between ``<!-- record-diagnostics NAME block=STEPS [methods=A,B] -->`` markers are
    this text."""

    rows = list(metrics_rows(Path(folder) / METRICS_FILE))
    _check_methods(record, [row["method"] for row in rows], methods)
    rows = [row for row in rows if methods is None or row["method"] in methods]
    steps = [int(row["env_steps"]) for row in rows]
    blocks = _blocks_of(record, steps, block_steps)
    settings = {row.get("setting") for row in rows}
    sums: dict[tuple[str, str, str], dict[int, list[float]]] = {}
    for row, block in zip(rows, blocks, strict=True):
        for column in DIAGNOSTICS:
            if row.get(column) not in (None, "", "nan"):
                key = (row["method"], row.get("setting"), column)
                sums.setdefault(key, {}).setdefault(int(block), []).append(float(row[column]))
    order = sorted({int(b) for b in blocks})
    lines = [
        f"| {_diagnostics_corner(record)} | "
        + " | ".join(_block_label(b, block_steps, max(steps)) for b in order)
        + " |",
        "|---|" + "---:|" * len(order),
    ]
    for (method, setting, column), values in sums.items():
        title, form = DIAGNOSTICS[column]
        name = display_name(method) + ("" if len(settings) == 1 else f" [{setting}]")
        cells = [form.format(np.mean(values[b])) if b in values else "-" for b in order]
        lines.append(f"| {name}: {title} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _diagnostics_corner(record: dict) -> str:
    """The diagnostics table's top-left cell: what its columns and its rows' cells are."""
    if record.get("rows") == "evaluated":
        return "M steps (means over the evaluated iterations)"
    return "M steps"


def _turn(steps: np.ndarray, values: np.ndarray, level: float) -> str:
    """The M steps of the first of three evaluations in a row above ``level``, or "never"."""
    above = values > level
    for first in range(len(values) - 2):
        if above[first : first + 3].all():
            return f"{steps[first] / 1e6:g}"
    return "never"


def seed_table(record: dict, folder: Path, turn: float, methods: list[str] | None = None) -> str:
    """Each seed of a recorded run, a row per (method, seed) (``methods``, default all):
    its final and late-average normalised return (the record's), its lowest evaluation and
    where, where it turned (the first of three evaluations in a row above ``turn``), and its
    confidence classifier's MAE on D_u (the record's ``confidence_mae``, for methods whose
    loss reads confidences). ``folder`` holds the checked ``record``. The docs' tables between
    ``<!-- record-seeds NAME turn=LEVEL [methods=A,B] -->`` markers are this text."""

    groups = read_evaluations(
        Path(folder) / METRICS_FILE, "normalized_return", evaluated_by="eval_return",
        group_by=("method", "setting"),
    )  # fmt: skip
    _check_methods(record, [method for method, _ in groups], methods)
    settings = {setting for _, setting in groups}
    lines = [
        f"| method | seed | final | {LATE_LABEL} | lowest evaluation (at M steps) | "
        f"turned above {turn:g} (M steps) | confidence MAE on D_u |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for (method, setting), (steps, values) in groups.items():
        if methods is not None and method not in methods:
            continue
        label = method if len(settings) == 1 else f"{method} [{setting}]"
        errors = (record.get("confidence_mae") or {}).get(label)
        for seed, row in enumerate(values):
            final, late = (
                record[statistic_key(name)][label][seed] for name in ("final", "late_average")
            )
            low = int(np.nanargmin(row)) if np.isfinite(row).any() else None
            lowest = "-" if low is None else f"{row[low]:.2f} ({steps[low] / 1e6:g})"
            if not reads_confidences(method):
                error = "reads none"
            elif errors is None or errors[seed] is None:
                error = "not recorded"
            else:
                error = f"{errors[seed]:.3f}"
            cells = [display_label(label), str(seed),
                     "diverged" if final is None else f"{final:.2f}",
                     "diverged" if late is None else f"{late:.2f}", lowest,
                     _turn(steps, row, turn), error]  # fmt: skip
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
