"""The prepared GPU check: what the paper's MuJoCo grid costs on an accelerator, in one run
under a deadline, as one JSON and one table.

    python benchmarks/gpu_check.py --json gpu_check.json   # on a GPU machine: 8 minutes at most
    python benchmarks/gpu_check.py --tiny --json dry.json  # a dry run at a tiny size (a CPU)

Its steps, in order of what matters most; each runs a script beside this one in a fresh
process, given what is left of ``--minutes``, and one that runs out of time is recorded as
such and the next begins:

1. Pendulum-v1's paper grid: 35 cells (7 methods x 5 seeds) of the table's settings, training
   steps/s, and the wall time the paper's 875 M steps would take at that rate.
2. Environment-only steps/s of each engine (``mjx``, and ``warp`` where the extra is
   installed) on Hopper, HalfCheetah, Walker2d, Swimmer and Ant -v4, 35 x 25 envs and ten
   times as wide.
3. 35-cell adversarial training steps/s with evaluation on Hopper-v4 for each engine, with the
   cold and warm compile (two fresh processes, an empty then a filled cache), then the other
   tasks without compile times, for as long as time is left; each task on the solver caps
   ``experiments.paper --preset gpu`` gives it (``paper.plan.GPU_SOLVERS``).

Every row carries the step, engine and task it measured, and ``status``: ``ok``, ``timed out
after N s``, ``failed: <last line>`` or ``skipped: no time left``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from common import markdown_table, write_rows

from pngail_jax import envs
from pngail_jax.paper.plan import GPU_SOLVERS

HERE = Path(__file__).resolve().parent
TASKS = ("Hopper-v4", "HalfCheetah-v4", "Walker2d-v4", "Swimmer-v4", "Ant-v4")
PAPER_GRID_STEPS = 7 * 5 * 5_000 * 5_000  # methods x seeds x iterations x steps per iteration
CELLS = 35
ENVS_PER_CELL = 25


@dataclass(frozen=True)
class Step:
    name: str  # "pendulum paper grid", "env only", "training"
    script: str
    argv: tuple[str, ...]
    engine: str = "-"
    task: str = "Pendulum-v1"


def gpu_engines() -> tuple[str, ...]:
    """The engines a GPU run can use: MJX's JAX implementation, and Warp where installed."""
    return tuple(engine for engine in envs.available_physics() if engine != "c")


def plan(tiny: bool) -> list[Step]:
    """The steps, most important first; ``tiny``: the smallest sizes that still run each."""
    engines = gpu_engines()
    tasks = TASKS[:1] if tiny else TASKS
    small = ("--iterations", "1", "--classifier-steps", "10", "--num-envs", "2",
             "--unroll-length", "20", "--eval-every", "1", "--num-eval-episodes", "1")  # fmt: skip
    pendulum = ("--sizes", "1", *small) if tiny else ("--sizes", str(CELLS))
    steps = [Step("pendulum paper grid", "grid_throughput.py",
                  ("--env", "Pendulum-v1", "--no-compile-times", *pendulum))]  # fmt: skip
    widths = "2" if tiny else f"{CELLS * ENVS_PER_CELL},{10 * CELLS * ENVS_PER_CELL}"
    for engine in engines:
        steps.append(
            Step(
                "env only",
                "env_throughput.py",
                ("--envs", ",".join(tasks), "--physics", engine, "--widths", widths),
                engine,
                ",".join(tasks),
            )  # fmt: skip
        )
    grid = ("--sizes", "1", *small) if tiny else ("--sizes", str(CELLS), "--iterations", "5")
    for index, task in enumerate(tasks):
        compiles = "--compile-times" if index == 0 and not tiny else "--no-compile-times"
        for engine in engines:
            # the caps the GPU preset trains this task on (gymnasium's own where none named)
            caps = ("--solver", GPU_SOLVERS[task]) if task in GPU_SOLVERS else ()
            argv = ("--env", task, "--physics", engine, compiles, *caps, *grid)
            steps.append(Step("training", "grid_throughput.py", argv, engine, task))
    return steps


def run_step(step: Step, seconds: float, out: Path) -> list[dict]:
    """The step's rows (each with the step, engine, task and status), or one row saying why
    it has none."""
    where = {"step": step.name, "engine": step.engine, "task": step.task}
    if seconds < 1:
        return [{**where, "status": "skipped: no time left"}]
    rows_path = out / f"{len(list(out.iterdir()))}.json"
    command = [sys.executable, str(HERE / step.script), *step.argv, "--json", str(rows_path)]
    if step.script == "env_throughput.py":
        command += ["--out", str(out / "env_throughput")]
    print(f"\n=== {step.name}: {step.task}, {step.engine} ({seconds:.0f} s left)", flush=True)
    start = time.perf_counter()
    try:
        result = subprocess.run(command, timeout=seconds, capture_output=True, text=True)
    except subprocess.TimeoutExpired:
        return [{**where, "status": f"timed out after {seconds:.0f} s"}]
    took = time.perf_counter() - start
    if result.returncode != 0 or not rows_path.exists():
        last = (result.stderr.strip().splitlines() or ["(no output)"])[-1]
        return [{**where, "status": f"failed: {last}", "seconds": took}]
    rows = json.loads(rows_path.read_text())
    return [{**where, **row, "status": "ok", "seconds": took} for row in rows]


def with_paper_estimate(row: dict) -> dict:
    """Pendulum's rows get the wall time of the paper's grid at their training rate."""
    rate = row.get("steps_per_second")
    if row["step"] == "pendulum paper grid" and row["status"] == "ok" and rate:
        return {**row, "paper_grid_seconds": PAPER_GRID_STEPS / rate}
    return row


def _number(value, form: str = ",.0f") -> str:
    return "-" if value is None else format(value, form)


def table(rows: list[dict]) -> str:
    header = ["step", "task", "engine", "cells / width", "steps/s", "incl. eval",
              "compile s cold / warm", "status"]  # fmt: skip
    cells = []
    for row in rows:
        size = row.get("cells", row.get("width", "-"))
        rate = row.get("steps_per_second")
        status = row["status"]
        if "paper_grid_seconds" in row:
            status += f"; the paper's grid: {row['paper_grid_seconds'] / 60:.1f} min"
        cells.append([
            row["step"], row.get("env", row["task"]), row["engine"], size, _number(rate),
            _number(row.get("steps_per_second_with_eval")),
            f"{_number(row.get('compile_seconds'), '.1f')} / "
            f"{_number(row.get('compile_seconds_warm'), '.1f')}",
            status,
        ])  # fmt: skip
    return markdown_table(header, cells, "lllrrrrl")


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=8.0, help="deadline (default 8)")
    parser.add_argument("--tiny", action="store_true", help="a dry run at the smallest sizes")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args(argv)
    if args.minutes <= 0:
        parser.error(f"--minutes must be positive, got {args.minutes}")
    deadline = time.perf_counter() + 60 * args.minutes
    rows = []
    with tempfile.TemporaryDirectory(prefix="gpu_check_") as scratch:
        for step in plan(args.tiny):
            rows += run_step(step, deadline - time.perf_counter(), Path(scratch))
    rows = [with_paper_estimate(row) for row in rows]
    print("\n" + table(rows), flush=True)
    write_rows(args.json, rows)
    return rows


if __name__ == "__main__":
    main()
