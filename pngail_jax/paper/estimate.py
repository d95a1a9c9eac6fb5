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


def read_throughput(path: Path) -> list[dict]:
    """The usable rows of a benchmark's JSON (a list of rows: a task, cells and a rate; rows
    a deadline cut short are left out), or RunError naming the file and the problem."""
    try:
        rows = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise RunError(f"--throughput {path}: cannot be read ({error})") from None
    if not isinstance(rows, list):
        raise RunError(f"--throughput {path}: not a benchmark's rows (a JSON list)")
    usable = [
        row
        for row in rows
        if isinstance(row, dict)
        and row.get("status", "ok") == "ok"
        and isinstance(row.get("env"), str)
        and isinstance(row.get("cells"), int)
        and _rate(row)
    ]
    if not usable:
        raise RunError(
            f"--throughput {path}: no row with a task, cells and a training rate (write one "
            "with benchmarks/gpu_check.py --json or benchmarks/grid_throughput.py --json)"
        )
    return usable


def _rate(row: dict) -> float | None:
    for key in RATE_KEYS:
        value = row.get(key)
        if isinstance(value, int | float) and value > 0 and math.isfinite(value):
            return float(value)
    return None


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
    settings = budget.run_settings(grid.task, physics)
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
        settings = budget.run_settings(task, physics, demos=True)
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
