"""Running a plan: each grid's demonstrations (the authors' file, or made once per task and
cut at each ratio a figure asks for), its ``RunConfig`` (``grid_config``) and one
``pngail_jax.jobs.sweep.run`` call per grid, resumed or kept as it stands."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path

from pngail_jax import envs
from pngail_jax.config.task import TASK_NUM_DEMOS
from pngail_jax.demos import (
    RELEASED_ACTION_SCALES,
    cut_mixture,
    load_demonstrations,
    load_npz,
    save_npz,
)
from pngail_jax.jobs import make_demos
from pngail_jax.jobs.chunks import format_seconds
from pngail_jax.jobs.make_demos import MakeDemosConfig
from pngail_jax.jobs.sweep import run
from pngail_jax.paper.plan import Budget, GridSpec, task_kind
from pngail_jax.storage.integrity import IntegrityError, atomic_path, read_json, write_json

# -- demonstrations --------------------------------------------------------------------------


def released_files(directory: Path | None, tasks: Sequence[str]) -> dict[str, Path]:
    """Task -> the authors' file in ``directory``, for each of ``tasks`` that has a usable one
    (a file serves every variant of its task, ``envs.task_family``: Hopper-v2's serves
    Hopper-v4 and Brax's Hopper)."""
    from pngail_jax.demos import RELEASED_TASKS

    if directory is None:
        return {}
    found = {}
    for file_env, file_task in RELEASED_TASKS.items():
        path = directory / f"{file_env}_mixture.npy"
        for task in tasks:
            if path.exists() and envs.task_family(task) == envs.task_family(file_task):
                found[task] = path
    return found


def made_demos_path(out: Path, task: str) -> Path:
    """Where a plan in ``out`` keeps ``task``'s made demonstrations (written last by the
    making, so its presence marks a finished one)."""
    return out / "demos" / task / make_demos.DEMOS_FILE


def demo_paths(
    grids, out: Path, budget: Budget, released: dict[str, Path], physics=None, learner="trpo"
):
    """The demonstrations file of every grid's set (made, mixed and saved when missing);
    made ones on ``physics`` (``Budget.settings_for``) by ``learner``'s policies."""
    sets = list(dict.fromkeys(grid.demos for grid in grids.values()))
    paths = {}
    for demo_set in sets:
        if demo_set.ratio is None:
            path = released[demo_set.task]
            scale = RELEASED_ACTION_SCALES.get(path.name.removesuffix("_mixture.npy"), 1.0)
            paths[demo_set] = (path, scale)
    made = [s for s in sets if s.ratio is not None]
    for task in dict.fromkeys(s.task for s in made):
        episode_steps = envs.make(task).max_episode_steps
        counts = {
            s: s.trajectory_counts(TASK_NUM_DEMOS.get(envs.task_family(task), 1), episode_steps)
            for s in made
            if s.task == task
        }
        full = made_demos_path(out, task)
        directory = full.parent
        if not full.exists():
            print(f"\n== demonstrations for {task}: making them into {directory}", flush=True)
            config = demo_config(task, budget, counts, physics, learner)
            make_plan_demonstrations(config, directory)
        source = load_npz(full)
        for demo_set, (optimal, intermediate) in counts.items():
            path = directory / f"{demo_set.name}.npz"
            if not path.exists():
                with atomic_path(path) as temporary:
                    mixed = cut_mixture(source, optimal, intermediate, demo_set.name)
                    mixed.metadata["source"] = (
                        f"experiments.paper: {demo_set.description}, from the made set"
                    )
                    save_npz(temporary, mixed)
            paths[demo_set] = (path, 1.0)
    return paths


def demo_config(
    task: str, budget: Budget, counts: dict, physics: str | None, learner: str = "trpo"
):
    """The making of ``task``'s demonstrations: enough optimal and intermediate trajectories
    for every set of ``counts`` (``{DemoSet: (optimal, intermediate)}``) at ``budget``."""
    num_optimal = max(c[0] for c in counts.values())
    num_intermediate = max(c[1] for c in counts.values())
    return MakeDemosConfig(
        env=task,
        iterations=budget.demo_iterations[task_kind(task)],
        seeds=budget.demo_seeds,
        num_trajectories=num_optimal + num_intermediate,
        ratio=f"{num_optimal}:{num_intermediate}",
        measure_episodes=budget.measure_episodes,
        settings=budget.settings_for(task, physics, demos=True),
        learner=learner,
    )


def make_plan_demonstrations(config, directory: Path) -> None:
    """``pngail_jax.jobs.make_demos.make_demonstrations`` into the plan's own ``directory`` (a
    making of the same config cut short there continues from its last block; any other
    making there is replaced)."""
    make_demos.make_demonstrations(config, directory, overwrite=True, continue_cut=True)


# -- grids -----------------------------------------------------------------------------------


def grid_config(
    grid: GridSpec,
    demos: tuple[Path, float],
    budget: Budget,
    num_rows: int | None,
    physics: str | None = None,
    learner: str = "trpo",
):
    """The ``RunConfig`` of a grid; ``num_rows``, the demonstrations' row count, is read only
    by a grid with fewer unlabelled rows (Fig. 6)."""
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.config.task import task_classifier, task_num_demos

    path, scale = demos
    label_ratios, num_demos = grid.label_ratios, None
    if grid.unlabelled_fraction != 1:  # the same n_c labelled rows, fewer unlabelled ones
        num_demos = task_num_demos(grid.task, num_rows)
        num_labelled = round(grid.label_ratios[0] * num_demos)
        num_demos = num_labelled + round(grid.unlabelled_fraction * (num_demos - num_labelled))
        label_ratios = (float(f"{num_labelled / num_demos:.6g}"),)
    classifier = task_classifier(grid.task)
    if budget.classifier_steps is not None:
        classifier = dataclasses.replace(classifier, num_steps=budget.classifier_steps)
    return RunConfig.preset(
        "smoke",
        env=grid.task,
        settings=budget.settings_for(grid.task, physics),
        classifier=classifier,
        methods=tuple(grid.methods),
        seeds=budget.seeds,
        iterations=budget.iterations,
        chunk_iterations=budget.chunk_iterations,
        label_ratios=tuple(label_ratios),
        noise_stds=tuple(grid.noise_stds),
        demos=str(Path(path).absolute()),
        action_scale=None if scale == 1.0 else scale,
        num_demos=num_demos,
        learner=learner,
        phase_sizes=budget.phase_sizes,
    )


def grid_complete(directory: Path) -> bool:
    """Whether a grid's summary.json says it is complete; a damaged one says no (the sweep's
    resume then writes it again from the checkpoints)."""
    from pngail_jax.storage.integrity import IntegrityError

    try:
        return bool(read_json(directory / "summary.json", "grid summary").get("complete"))
    except (FileNotFoundError, IntegrityError, AttributeError):
        return False


def run_grid(
    grid: GridSpec, directory: Path, config, command: list[str], allow_unsealed: bool = False
) -> bool:
    """Runs (or resumes) one grid with ``pngail_jax.jobs.sweep.run``, or keeps a complete one
    (returns True then). ``allow_unsealed``: resume a grid whose config seal is missing. A
    refusal raises ``RunError``."""
    if grid_complete(directory):
        print(f"\n== {grid.name}: done, kept ({directory})", flush=True)
        return True
    resume = (directory / "config.json").exists()
    if resume:
        print(f"\n== {grid.name}: resuming {directory}", flush=True)
    else:
        print(f"\n== {grid.name}: {grid.demos.description}", flush=True)
    run(None if resume else config, directory, resume=resume, command=command,
        allow_unsealed=allow_unsealed)  # fmt: skip
    return False


def planned_configs(grids, demos, budget: Budget, physics, learner: str = "trpo") -> dict:
    """``{name: RunConfig}`` of every grid of the plan (``grid_config``); the row count of a
    demonstration set is read only for a grid with fewer unlabelled rows (Fig. 6)."""
    num_rows = {}
    configs = {}
    for name, grid in grids.items():
        path, scale = demos[grid.demos]
        if grid.unlabelled_fraction != 1 and grid.demos not in num_rows:
            num_rows[grid.demos] = load_demonstrations(path, action_scale=scale).num_rows
        configs[name] = grid_config(
            grid, demos[grid.demos], budget, num_rows.get(grid.demos), physics, learner
        )
    return configs


def run_grids(
    grids, configs: dict, out: Path, command: list[str], allow_unsealed: bool = False
) -> dict:
    """Runs (or resumes, or keeps) every grid with its config (``planned_configs``); each
    grid's wall-clock seconds over all calls, interrupted ones included, kept in
    ``out/timings.json``. ``command``: the plan's, recorded in each grid's config."""
    timings_path = out / "timings.json"
    try:
        timings = read_json(timings_path, "timings record") if timings_path.exists() else {}
    except IntegrityError as error:
        print(f"note: {error}; wall times start again from this call")
        timings = {}
    ran: list[float] = []  # seconds of the grids this call ran
    for index, (name, grid) in enumerate(grids.items()):
        print(f"\n== grid {index + 1} of {len(grids)}{plan_eta(ran, len(grids) - index)}")
        start, kept = time.perf_counter(), False
        try:
            kept = run_grid(grid, out / "grids" / name, configs[name], command, allow_unsealed)
        finally:  # an interrupted call (Ctrl-C, SIGTERM) counts its time too
            if not kept:
                ran.append(time.perf_counter() - start)
                timings[name] = timings.get(name, 0.0) + ran[-1]
                write_json(timings_path, timings)
    return timings


def plan_eta(seconds: list[float], remaining: int) -> str:
    """', about T left for the plan' from the mean of the grids run so far (grids differ, so a
    rough guide), or '' before any has run."""
    if not seconds:
        return ""
    return f", about {format_seconds(remaining * sum(seconds) / len(seconds))} left for the plan"
