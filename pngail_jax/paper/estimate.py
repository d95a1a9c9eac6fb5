"""The plan's wall time, estimated before it starts from measured throughput.

The measurements are a benchmark's rows (``python benchmarks/gpu_check.py --json FILE`` or
``python benchmarks/grid_throughput.py --json FILE`` on the machine that will run the plan):
each gives a task's adversarial training steps per second for a grid of some number of cells,
evaluation included where it was measured. A grid's estimate is its environment steps over
the rate of the row for its task (and engine, where the row names one) whose cell count is
nearest its own, plus that row's compile seconds; a task's made demonstrations are estimated
the same way, at the rate of the row nearest their seeds (TRPO alone skips the
discriminator, so this errs long). Grids differ from the measured chunk (methods, phases), so
the figure is a guide, not a promise; the plan's progress lines correct it as grids finish.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from pngail_jax import envs
from pngail_jax.jobs.chunks import format_seconds
from pngail_jax.jobs.errors import RunError
from pngail_jax.paper.plan import Budget, GridSpec, task_kind

RATE_KEYS = ("steps_per_second_with_eval", "steps_per_second")  # the first one present
ENVIRONMENT_ONLY = "env_step"  # the name of env_throughput's rows (in gpu_check's too)


def read_throughput(path: Path) -> list[dict]:
    """The usable rows of a benchmark's JSON (a list of rows: a task, cells and a rate), or
    RunError naming the file, the row (counted from 1), the field and its value. Rows a
    deadline cut short or that failed (``status`` other than ``ok``) and environment-only rows
    are left out; every other row is a training measurement, and each field the estimate reads
    is checked (``check_row``), so a bad number is refused here, not met halfway through the
    plan. Fields the estimate does not read are not looked at."""
    try:
        rows = json.loads(Path(path).read_text())
    except (OSError, ValueError, RecursionError) as error:
        raise RunError(f"--throughput {path}: cannot be read ({error})") from None
    if not isinstance(rows, list):
        raise RunError(
            f"--throughput {path}: not a benchmark's rows (a JSON list), got {_shown(rows)}"
        )
    for number, row in enumerate(rows, start=1):
        problem = check_row(row)
        if problem:
            known = isinstance(row, dict) and row.get("env") in envs.ENV_NAMES
            task = f" ({row['env']})" if known else ""  # an unknown one, the problem shows
            raise RunError(f"--throughput {path}: row {number}{task}: {problem}")
    usable = [row for row in rows if _measures_training(row)]
    if not usable:
        raise RunError(
            f"--throughput {path}: no row with a task, cells and a training rate (write one "
            "with benchmarks/gpu_check.py --json or benchmarks/grid_throughput.py --json)"
        )
    return usable


def check_row(row) -> str | None:
    """What is wrong with one row of a throughput file, or None. A training row needs
    ``env`` (a task of ``envs.ENV_NAMES``), ``cells`` (a whole number above 0) and a rate
    (``RATE_KEYS``: steps per second, finite and above 0); ``compile_seconds`` (finite, 0 or
    more) and ``physics`` (an engine of ``envs.PHYSICS``) are optional, JSON null meaning not
    measured."""
    if not isinstance(row, dict):
        return f"{_shown(row)} is not a JSON object"
    status = row.get("status", "ok")
    if not isinstance(status, str):
        return f"status {_shown(status)} is not a string"
    if not _measures_training(row):
        return None
    if row.get("env") is None:
        return "env (the task) is missing"
    if not isinstance(row["env"], str) or row["env"] not in envs.ENV_NAMES:
        return f"env {_shown(row['env'])} is not a known task ({', '.join(envs.ENV_NAMES)})"
    cells = row.get("cells")
    if cells is None:
        return "cells is missing"
    if isinstance(cells, bool) or not isinstance(cells, int) or cells < 1:
        return f"cells {_shown(cells)} is not a whole number above 0"
    rates = [key for key in RATE_KEYS if row.get(key) is not None]
    if not rates:
        return f"no training rate: {' or '.join(RATE_KEYS)} is missing"
    problems = [_number_problem(key, row[key], above_zero=True) for key in rates]
    if row.get("compile_seconds") is not None:
        problems.append(_number_problem("compile_seconds", row["compile_seconds"]))
    physics = row.get("physics")
    if physics is not None and (not isinstance(physics, str) or physics not in envs.PHYSICS):
        problems.append(f"physics {_shown(physics)} is not an engine ({', '.join(envs.PHYSICS)})")
    return next((problem for problem in problems if problem), None)


def _measures_training(row: dict) -> bool:
    """Whether the estimate reads ``row``: a measurement that finished, of training."""
    return row.get("status", "ok") == "ok" and row.get("name") != ENVIRONMENT_ONLY


def _number_problem(field: str, value, above_zero: bool = False) -> str | None:
    """What keeps ``value`` from being ``field``'s number: not a number (a boolean is not
    one), NaN or infinite, negative, or with ``above_zero`` 0 too; None if it is one."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return f"{field} {_shown(value)} is not a number"
    try:
        finite = math.isfinite(value)
    except OverflowError:  # a whole number too large for a float
        finite = False
    if not finite:
        return f"{field} {_shown(value)} is not finite"
    if value < 0:
        return f"{field} {_shown(value)} is negative"
    if above_zero and value == 0:
        return f"{field} {_shown(value)} is not above 0"
    return None


def _shown(value, limit: int = 40) -> str:
    """``value`` as the file spells it (JSON), cut short at ``limit`` characters."""
    text = json.dumps(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def _rate(row: dict) -> float:
    """The training rate of a checked row: its first rate of ``RATE_KEYS`` given."""
    return float(next(row[key] for key in RATE_KEYS if row.get(key) is not None))


def nearest_row(rows: list[dict], task: str, physics: str | None, cells: int) -> dict | None:
    """The row of ``task`` whose cell count is nearest ``cells`` on a log scale, or None; for
    gymnasium's MuJoCo tasks only rows of the engine the plan runs on (``physics``, None: this
    machine's default) count."""
    engine = (physics or envs.default_physics()) if task in envs.GYM_TASKS else None
    candidates = [
        row
        for row in rows
        if row["env"] == task and (engine is None or row.get("physics") in (None, engine))
    ]
    if not candidates:
        return None
    return min(candidates, key=lambda row: abs(math.log(row["cells"] / cells)))


def grid_size(grid: GridSpec, budget: Budget, physics: str | None) -> tuple[int, int]:
    """(cells, environment steps) of ``grid`` at ``budget``."""
    settings = budget.settings_for(grid.task, physics)
    cells = len(grid.methods) * budget.seeds * len(grid.label_ratios) * len(grid.noise_stds)
    return cells, cells * budget.iterations * settings.num_envs * settings.unroll_length


def _seconds(row: dict, steps: int) -> float:
    return steps / _rate(row) + float(row.get("compile_seconds") or 0.0)


def estimate_table(grids: dict, budget: Budget, physics, rows: list[dict], made_tasks) -> str:
    """The estimate as text: a row per grid (its cells, steps, the measured row it reads and
    its time), one per task whose demonstrations are made, and the total, naming what no
    measurement covers."""
    lines = [
        "| grid | task | cells | env steps | measured rate (at cells) | estimate |",
        "|---|---|---:|---:|---:|---:|",
    ]
    total, missing = 0.0, []
    parts = [(name, grid.task, *grid_size(grid, budget, physics)) for name, grid in grids.items()]
    for task in made_tasks:
        settings = budget.settings_for(task, physics, demos=True)
        iterations = budget.demo_iterations[task_kind(task)]
        steps = budget.demo_seeds * iterations * settings.num_envs * settings.unroll_length
        parts.append((f"demonstrations of {task}", task, budget.demo_seeds, steps))
    for name, task, cells, steps in parts:
        row = nearest_row(rows, task, physics, cells)
        if row is None:
            missing.append(task)
            lines.append(f"| {name} | {task} | {cells} | {steps:,} | not measured | - |")
            continue
        seconds = _seconds(row, steps)
        total += seconds
        lines.append(
            f"| {name} | {task} | {cells} | {steps:,} | {_rate(row):,.0f} ({row['cells']}) "
            f"| {format_seconds(seconds)} |"
        )
    gaps = sorted(set(missing))
    tail = f"; not measured, so not counted: {', '.join(gaps)}" if gaps else ""
    return "\n".join(lines) + f"\n\nabout {format_seconds(total)} in all{tail}"
