"""Reproduce the paper's figures and tables: the grids behind them and one results page.

    python -m experiments.paper --preset check     # all of it on a 2-core CPU (under an hour)
    python -m experiments.paper --preset paper --released-demos data/released   # a GPU
    python -m experiments.paper --only fig2,table1 --envs Hopper,Pendulum-v1
    python -m experiments.paper --resume results/paper-20261123-120000

Each figure is a set of ``experiments.sweep`` grids, one compiled program per task and
demonstration set (a task's Fig. 2 and Fig. 3 share one grid of the seven methods). The
demonstrations come from ``--released-demos DIR`` where it holds the authors' file for a task
(``Hopper-v2_mixture.npy`` ...; each file's known action scale applied), else from one
``experiments.make_demos`` run per task, whose trajectories are mixed at each ratio a figure
asks for. Writes ``DIR/README.md`` (every figure's plot and table beside the paper's numbers,
each with the command that makes it alone), ``DIR/<figure>.png``, ``DIR/results.json``,
``DIR/demos/`` and one sweep directory per grid in ``DIR/grids/``. An interrupted run continues
with ``--resume DIR``: finished grids are kept, an unfinished one resumes from its checkpoint.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
import types
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pngail_jax import compilation, envs
from pngail_jax.integrity import atomic_write_text, read_json, seal, write_json
from pngail_jax.methods import display_name, required_phases
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    RunLocked,
    claim_output,
    known_names,
    note_deprecated,
    output_refusal,
    path_argument,
    prepare_output,
    run_lock,
)
from pngail_jax.report import group_label, late_evaluations, line_style

FIG2_METHODS = ("gail", "2iwil", "icgail", "wgail", "pngail")
FIG3_METHODS = ("pngail", "pngail-no-bsc", "pngail-no-pn")
SEVEN_METHODS = ("gail", "2iwil", "icgail", "wgail", "pngail", "pngail-no-bsc", "pngail-no-pn")
# The paper's six tasks: its MuJoCo tasks as gymnasium's -v4 (gym -v2's model files and
# observations). Figures name tasks by family (``envs.task_family``), so Brax's variants
# (``--envs Hopper``) fill the same panels.
MUJOCO_TASKS = envs.GYM_TASKS
PAPER_TASKS = ("Pendulum-v1", *MUJOCO_TASKS)
FIGURES = (
    "fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "table1", "table4",
)  # fmt: skip
# Fig. 5 / Table 4: PN-GAIL against the appendix baselines (and the two BC baselines).
APPENDIX_COMPARISON = (
    "pngail", "cail", "trex", "drex", "firl-fkl", "firl-rkl", "firl-js", "bc", "bc-weighted",
)  # fmt: skip
PAPER_TABLE4 = {  # method: (Pendulum-v1, Ant-v2) "average reward after training convergence"
    "pngail": ((-465.978, 132.710), (2960.458, 851.465)),
    "cail": ((-697.821, 91.459), (2336.546, 735.378)),
    "trex": ((-1074.435, 258.078), (-1858.025, 217.228)),
    "drex": ((-1532.958, 114.138), (-2495.473, 220.703)),
    "firl-fkl": ((-698.064, 300.793), (1563.796, 1372.482)),
    "firl-rkl": ((-603.760, 189.727), (962.785, 816.547)),
    "firl-js": ((-581.602, 185.096), (882.026, 690.371)),
}
PAPER_TABLE4_OPTIMAL = (-116.81, 4271.79)
LABEL_RATIOS = (0.2, 0.1, 0.05, 0.03)  # Fig. 4 (a), (b)
NOISE_STDS = (0.0, 0.2, 0.4)  # Fig. 4 (c)
# Fig. 6 and Fig. 10 name proportions in their legends but not in the text: ours.
UNLABELLED_FRACTIONS = (1.0, 0.5, 0.25)
INTERMEDIATE_FRACTIONS = (1.0, 0.5, 0.25)
PAPER_TABLE1 = {  # task: (SC MAE, SC RMSE, BSC MAE, BSC RMSE), means over the paper's seeds
    "Ant": (0.213, 0.345, 0.056, 0.212),
    "HalfCheetah": (0.184, 0.272, 0.057, 0.175),
    "Hopper": (0.307, 0.519, 0.169, 0.371),
    "Pendulum-v1": (0.126, 0.164, 0.097, 0.138),
    "Swimmer": (0.362, 0.595, 0.286, 0.472),
    "Walker2d": (0.132, 0.246, 0.014, 0.101),
}


@dataclasses.dataclass(frozen=True)
class Budget:
    """How long every grid and demonstration run is; ``settings`` and ``demo_settings`` are
    ``RunSettings`` fields per task kind over the task's row of ``pngail_jax.settings``."""

    iterations: int
    seeds: int
    chunk_iterations: int
    classifier_steps: int | None  # None: the task's (25,000; 50,000 on Walker2d)
    demo_iterations: dict[str, int]  # per task kind: "pendulum" / "mujoco"
    demo_seeds: int
    measure_episodes: int
    settings: dict[str, dict[str, int]]  # per task kind
    demo_settings: dict[str, dict[str, int]]

    def run_settings(self, task: str, physics: str | None, demos: bool = False):
        """The ``RunSettings`` of ``task``'s grids (``demos``: of its demonstration making,
        which evaluates every 10 iterations unless the budget says otherwise) on
        ``physics`` (gymnasium's MuJoCo tasks only; None: the platform's engine)."""
        from pngail_jax.settings import settings_for

        kind = task_kind(task)
        fields = {"eval_every": 10, **self.demo_settings[kind]} if demos else self.settings[kind]
        engine = physics if task in envs.GYM_TASKS else None
        return settings_for(task, **fields, physics=engine)


NO_SETTINGS = {"pendulum": {}, "mujoco": {}}  # every task's own row
BUDGETS = {
    # Every figure on a 2-core CPU: a check that everything runs, not a result.
    "check": Budget(
        iterations=20,
        seeds=2,
        chunk_iterations=10,
        classifier_steps=500,
        demo_iterations={"pendulum": 40, "mujoco": 10},
        demo_seeds=1,
        measure_episodes=2,
        settings={
            "pendulum": {"eval_every": 10, "num_eval_episodes": 8},
            "mujoco": {
                "num_envs": 5,
                "unroll_length": 100,
                "eval_every": 10,
                "num_eval_episodes": 1,
            },
        },  # fmt: skip
        demo_settings={
            "pendulum": {"eval_every": 10},
            "mujoco": {
                "num_envs": 5,
                "unroll_length": 100,
                "eval_every": 5,
                "num_eval_episodes": 1,
            },
        },  # fmt: skip
    ),
    # The paper's budget: 5,000 TRPO iterations of about 5,000 steps, 5 seeds (a GPU).
    "paper": Budget(
        iterations=5_000,
        seeds=5,
        chunk_iterations=250,
        classifier_steps=None,
        demo_iterations={"pendulum": 300, "mujoco": 2_000},
        demo_seeds=3,
        measure_episodes=64,
        settings=NO_SETTINGS,
        demo_settings=NO_SETTINGS,
    ),
    # A tenth of the paper's budget (2.5 M steps per run): Pendulum-v1 grids in about half
    # an hour each on a 2-core CPU, the MuJoCo grids of the authors' files on the C engine in
    # 1.5-2 hours each (Hopper-v4: 122 minutes beside other jobs; docs/results.md).
    "cpu": Budget(
        iterations=500,
        seeds=5,
        chunk_iterations=100,
        classifier_steps=None,
        demo_iterations={"pendulum": 150, "mujoco": 300},
        demo_seeds=3,
        measure_episodes=64,
        settings=NO_SETTINGS,
        demo_settings=NO_SETTINGS,
    ),
    # The test suite's: Pendulum-v1 in seconds.
    "test": Budget(
        iterations=4,
        seeds=2,
        chunk_iterations=2,
        classifier_steps=50,
        demo_iterations={"pendulum": 4, "mujoco": 2},
        demo_seeds=1,
        measure_episodes=2,
        settings={
            "pendulum": {
                "num_envs": 4,
                "unroll_length": 50,
                "eval_every": 2,
                "num_eval_episodes": 2,
            },
            "mujoco": {"num_envs": 2, "unroll_length": 16, "eval_every": 2, "num_eval_episodes": 1},
        },  # fmt: skip
        demo_settings={
            "pendulum": {"num_envs": 4, "unroll_length": 50, "eval_every": 2},
            "mujoco": {"num_envs": 2, "unroll_length": 16, "eval_every": 1, "num_eval_episodes": 1},
        },  # fmt: skip
    ),
}


# Presets renamed so that one name means one scale in every program: {old: new}.
RENAMED_BUDGETS = {"smoke": "check"}


def task_kind(task: str) -> str:
    return "pendulum" if task == "Pendulum-v1" else "mujoco"


@dataclasses.dataclass(frozen=True)
class DemoSet:
    """A task's demonstrations: the authors' file (``ratio`` None) or a mixture of the made
    optimal and intermediate trajectories at ``ratio``, keeping ``intermediate_fraction`` of
    the intermediate ones (Fig. 10)."""

    task: str
    ratio: tuple[int, int] | None
    intermediate_fraction: float = 1.0

    @property
    def name(self) -> str:
        if self.ratio is None:
            return "released"
        name = f"made-{self.ratio[0]}to{self.ratio[1]}"
        return name if self.intermediate_fraction == 1 else f"{name}-{self.intermediate_fraction:g}"

    @property
    def description(self) -> str:
        if self.ratio is None:
            return "the authors' file"
        text = f"made, {self.ratio[0]}:{self.ratio[1]}"
        if self.intermediate_fraction != 1:
            text += f", {self.intermediate_fraction:g} of the intermediate trajectories"
        return text

    def trajectory_counts(self, min_rows: int, episode_steps: int) -> tuple[int, int]:
        """(optimal, intermediate) trajectories: the ratio scaled up until full-length
        episodes give ``min_rows`` rows, then the intermediate fraction applied."""
        optimal, intermediate = self.ratio
        scale = max(1, math.ceil(min_rows / (episode_steps * (optimal + intermediate))))
        return optimal * scale, max(1, round(intermediate * scale * self.intermediate_fraction))


@dataclasses.dataclass(frozen=True)
class GridSpec:
    """One sweep: a task, a demonstration set, methods and the grid axes."""

    name: str
    task: str
    demos: DemoSet
    methods: tuple[str, ...]
    label_ratios: tuple[float, ...] = (0.2,)
    noise_stds: tuple[float, ...] = (0.0,)
    unlabelled_fraction: float = 1.0  # Fig. 6: n_c kept, n_u scaled


@dataclasses.dataclass(frozen=True)
class Series:
    """One curve / table row of a figure: a method (at a setting) of a grid."""

    label: str
    grid: str
    method: str
    setting: str | None = None  # the sweep's setting label; None: the grid's only one


@dataclasses.dataclass(frozen=True)
class Figure:
    name: str
    title: str
    paper: str  # what the paper reports
    panels: dict[str, list[Series]]  # per task


def main_grid(task: str, released: bool) -> GridSpec:
    demos = DemoSet(task, None if released else (1, 4))
    return GridSpec(f"{task}-main", task, demos, SEVEN_METHODS)


def appendix_groups(task: str) -> dict[str, tuple[str, ...]]:
    """Fig. 5 / Table 4's grids on ``task``: one per set of training phases
    (``methods.required_phases``), so that no cell runs a phase it does not read (a vmapped
    grid runs every compiled phase in every cell; f-IRL's discriminator refits would
    otherwise run in all 45 cells). Same seeds, so the common random numbers hold."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for method in APPENDIX_COMPARISON:
        groups.setdefault(required_phases((method,)), []).append(method)
    return {
        f"{task}-appendix-{methods[0].split('-')[0]}": tuple(methods) for methods in groups.values()
    }


# The appendix grids from cheap to dear on a CPU (measured per cell on Pendulum-v1, before
# RL: T-REX's reward fit ~200 s, D-REX's clone and 3 fits ~910 s, f-IRL's refits ~10 s per
# iteration), so that a run cut short has the most grids done.
APPENDIX_COST_ORDER = ("pngail", "bc", "cail", "trex", "drex", "firl")


def _appendix_cost(name: str) -> int:
    group = name.rsplit("-", 1)[1]
    return APPENDIX_COST_ORDER.index(group) if group in APPENDIX_COST_ORDER else 0


class Planner:
    """The grids a plan has so far, for the figures' builders: each adds the grids it reads
    (a grid two figures share is run once) and returns its ``Figure``."""

    def __init__(self, tasks: Sequence[str], released: set[str]):
        self.tasks, self.released = list(tasks), released
        self.grids: dict[str, GridSpec] = {}

    def add(self, grid: GridSpec) -> str:
        self.grids.setdefault(grid.name, grid)
        return grid.name

    def per_method(self, grid: GridSpec, methods) -> list[Series]:
        name = self.add(grid)
        return [Series(method, name, method) for method in methods]

    def main_of(self, task: str) -> GridSpec:
        return main_grid(task, task in self.released)

    def pick(self, families) -> list[str]:
        """The plan's tasks of ``families`` (a figure's tasks), in the families' order."""
        return [
            task for family in families for task in self.tasks if envs.task_family(task) == family
        ]


def plan(figures: Sequence[str], tasks: Sequence[str], released: set[str]):
    """The figures asked for (on the tasks asked for) and the grids behind them."""
    planner = Planner(tasks, released)
    made = [FIGURE_BUILDERS[figure](planner, figure) for figure in figures]
    return [figure for figure in made if figure.panels], planner.grids


def fig2_or_fig3(planner: Planner, figure: str) -> Figure:
    methods = FIG2_METHODS if figure == "fig2" else FIG3_METHODS
    what = "PN-GAIL and the baselines" if figure == "fig2" else "the ablations"
    claim = "every baseline" if figure == "fig2" else "both ablations"
    return Figure(
        figure,
        f"Fig. {figure[3:]}: {what}, every task",
        f"PN-GAIL above {claim} on all six tasks (the figure is a plot; its values are not in "
        "the text)",
        {task: planner.per_method(planner.main_of(task), methods) for task in planner.tasks},
    )


def table1(planner: Planner, figure: str) -> Figure:
    return Figure(
        figure,
        "Table 1: the confidence classifiers' error on D_u (SC vs BSC)",
        "BSC's MAE and RMSE below SC's on every task",
        {
            task: planner.per_method(planner.main_of(task), ("pngail-no-bsc", "pngail"))
            for task in planner.tasks
        },
    )


def fig5_or_table4(planner: Planner, figure: str) -> Figure:
    panels = {}
    for task in planner.pick(("Pendulum-v1", "Ant")):
        main = planner.main_of(task)
        demos = main.demos if task == "Pendulum-v1" else DemoSet(task, (1, 10))
        groups = appendix_groups(task)
        for name in sorted(groups, key=_appendix_cost):  # the cheap grids first
            planner.add(GridSpec(name, task, demos, groups[name]))
        panels[task] = [
            series
            for name, methods in groups.items()
            for series in planner.per_method(GridSpec(name, task, demos, methods), methods)
        ]
    return Figure(
        figure,
        "Fig. 5: PN-GAIL against the appendix baselines"
        if figure == "fig5"
        else "Table 4: average return during training, against the appendix baselines",
        "PN-GAIL above CAIL, T-REX, D-REX and f-IRL (the demonstrations of Fig. 2 on "
        "Pendulum-v1, of Fig. 8 on Ant; rankings by every trajectory's confidence)",
        panels,
    )


def fig4(planner: Planner, figure: str) -> Figure:
    panels = {}
    for task in planner.pick(("Ant", "Hopper")):
        grid = dataclasses.replace(
            planner.main_of(task), name=f"{task}-label-ratios", methods=("pngail",),
            label_ratios=LABEL_RATIOS,
        )  # fmt: skip
        name = planner.add(grid)
        panels[task] = [
            Series(f"label ratio {r:g}", name, "pngail", f"label_ratio={r:g},noise=0")
            for r in LABEL_RATIOS
        ]
    if "Pendulum-v1" in planner.tasks:
        grid = dataclasses.replace(
            planner.main_of("Pendulum-v1"), name="Pendulum-v1-noise", methods=("pngail",),
            noise_stds=NOISE_STDS,
        )  # fmt: skip
        name = planner.add(grid)
        panels["Pendulum-v1"] = [
            Series(f"noise {s:g}", name, "pngail", f"label_ratio=0.2,noise={s:g}")
            for s in NOISE_STDS
        ]
    return Figure(
        figure,
        "Fig. 4: label ratios 0.2-0.03 (Ant, Hopper), confidence noise (Pendulum-v1)",
        "only a marginal decline as the label ratio falls; robust to noise",
        panels,
    )


def fig6(planner: Planner, figure: str) -> Figure:
    panels = {}
    for task in planner.pick(("Pendulum-v1",)):
        panels[task] = []
        for fraction in UNLABELLED_FRACTIONS:
            main = planner.main_of(task)
            grid = dataclasses.replace(
                main, name=f"{task}-unlabelled-{fraction:g}", methods=("pngail",),
                unlabelled_fraction=fraction,
            )  # fmt: skip
            name = planner.add(grid if fraction != 1 else main)
            panels[task].append(Series(f"{fraction:g} of D_u", name, "pngail"))
    return Figure(
        figure,
        "Fig. 6: fewer unlabelled rows (the paper does not name its task: ours is Pendulum-v1)",
        "returns rise with the amount of unlabelled data",
        panels,
    )


def fig7(planner: Planner, figure: str) -> Figure:
    panels = {}
    for task in planner.pick(("Pendulum-v1",)):
        panels[task] = []
        for ratio in ((2, 3), (1, 4), (1, 9)):
            grid = GridSpec(
                f"{task}-made-{ratio[0]}to{ratio[1]}-pngail", task, DemoSet(task, ratio),
                ("pngail",),
            )  # fmt: skip
            if planner.main_of(task).demos == grid.demos:  # the main grid has these cells
                grid = planner.main_of(task)
            panels[task].append(Series(f"{ratio[0]}:{ratio[1]}", planner.add(grid), "pngail"))
    return Figure(
        figure,
        "Fig. 7: optimal:intermediate 2:3, 1:4, 1:9 (Pendulum-v1, made sets)",
        "the more optimal demonstrations, the higher the return",
        panels,
    )


def fig8_or_fig9(planner: Planner, figure: str) -> Figure:
    ratio = (1, 10) if figure == "fig8" else (2, 1)
    task_names = ("Ant",) if figure == "fig8" else ("Ant", "Pendulum-v1")
    panels = {
        task: planner.per_method(
            GridSpec(
                f"{task}-made-{ratio[0]}to{ratio[1]}", task, DemoSet(task, ratio), FIG2_METHODS
            ),
            FIG2_METHODS,
        )  # fmt: skip
        for task in planner.pick(task_names)
    }
    return Figure(
        figure,
        f"Fig. {figure[3:]}: optimal:intermediate {ratio[0]}:{ratio[1]} "
        f"({', '.join(task_names)}, made sets)",
        "only PN-GAIL learns from the extreme 1:10 mixture"
        if figure == "fig8"
        else "PN-GAIL stays best when optimal demonstrations dominate",
        panels,
    )


def fig10(planner: Planner, figure: str) -> Figure:
    panels = {}
    for task in planner.pick(("Ant",)):
        panels[task] = []
        for fraction in INTERMEDIATE_FRACTIONS:
            demos = DemoSet(task, (1, 4), fraction)
            grid = GridSpec(f"{task}-{demos.name}-pngail", task, demos, ("pngail",))
            name = planner.add(grid if fraction != 1 else main_grid(task, False))
            panels[task].append(Series(f"{fraction:g} of non-optimal", name, "pngail"))
    return Figure(
        figure,
        "Fig. 10: fewer non-optimal demonstrations (Ant, made 1:4 set)",
        "no significant decline with fewer non-optimal demonstrations",
        panels,
    )


# Each figure's builder: (planner, figure name) -> Figure, adding the grids it reads.
FIGURE_BUILDERS = {
    "fig2": fig2_or_fig3, "fig3": fig2_or_fig3, "table1": table1, "fig4": fig4,
    "fig5": fig5_or_table4, "table4": fig5_or_table4, "fig6": fig6, "fig7": fig7,
    "fig8": fig8_or_fig9, "fig9": fig8_or_fig9, "fig10": fig10,
}  # fmt: skip


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


def demo_paths(grids, out: Path, budget: Budget, released: dict[str, Path], physics=None):
    """The demonstrations file of every grid's set (made, mixed and saved when missing);
    made ones on ``physics`` (``Budget.run_settings``)."""
    from pngail_jax.demos import RELEASED_ACTION_SCALES, load_npz, save_npz
    from pngail_jax.demos.make import cut_mixture
    from pngail_jax.integrity import atomic_path
    from pngail_jax.run_config import TASK_NUM_DEMOS

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
        directory = out / "demos" / task
        full = directory / "demos.npz"
        if not full.exists():
            print(f"\n== demonstrations for {task}: making them into {directory}", flush=True)
            make_demonstrations(demo_config(task, budget, counts, physics), directory)
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


def demo_config(task: str, budget: Budget, counts: dict, physics: str | None):
    """The making of ``task``'s demonstrations: enough optimal and intermediate trajectories
    for every set of ``counts`` (``{DemoSet: (optimal, intermediate)}``) at ``budget``."""
    from pngail_jax.demos.make import MakeDemosConfig

    num_optimal = max(c[0] for c in counts.values())
    num_intermediate = max(c[1] for c in counts.values())
    return MakeDemosConfig(
        env=task,
        iterations=budget.demo_iterations[task_kind(task)],
        seeds=budget.demo_seeds,
        num_trajectories=num_optimal + num_intermediate,
        ratio=f"{num_optimal}:{num_intermediate}",
        measure_episodes=budget.measure_episodes,
        settings=budget.run_settings(task, physics, demos=True),
    )


def make_demonstrations(config, directory: Path) -> None:
    """``pngail_jax.demos.make.make_demonstrations`` into the plan's own ``directory`` (a
    making cut short there is replaced); a refusal ends the program in one line."""
    from pngail_jax.demos import make
    from pngail_jax.runner import RunError

    try:
        make.make_demonstrations(config, directory, overwrite=True)
    except RunError as error:
        raise SystemExit(str(error)) from None


# -- grids -----------------------------------------------------------------------------------


def grid_config(
    grid: GridSpec,
    demos: tuple[Path, float],
    budget: Budget,
    num_rows: int | None,
    physics: str | None = None,
):
    """The ``RunConfig`` of a grid; ``num_rows``, the demonstrations' row count, is read only
    by a grid with fewer unlabelled rows (Fig. 6)."""
    from pngail_jax.run_config import RunConfig, task_classifier

    path, scale = demos
    label_ratios, num_demos = grid.label_ratios, None
    if grid.unlabelled_fraction != 1:  # the same n_c labelled rows, fewer unlabelled ones
        num_demos = RunConfig(env=grid.task).task_num_demos(num_rows)
        num_labelled = round(grid.label_ratios[0] * num_demos)
        num_demos = num_labelled + round(grid.unlabelled_fraction * (num_demos - num_labelled))
        label_ratios = (float(f"{num_labelled / num_demos:.6g}"),)
    classifier = task_classifier(grid.task)
    if budget.classifier_steps is not None:
        classifier = dataclasses.replace(classifier, num_steps=budget.classifier_steps)
    return RunConfig.preset(
        "smoke",
        env=grid.task,
        settings=budget.run_settings(grid.task, physics),
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
    )


def grid_complete(directory: Path) -> bool:
    """Whether a grid's summary.json says it is complete; a damaged one says no (the sweep's
    resume then writes it again from the checkpoints)."""
    from pngail_jax.integrity import IntegrityError

    try:
        return bool(read_json(directory / "summary.json", "grid summary").get("complete"))
    except (FileNotFoundError, IntegrityError, AttributeError):
        return False


def run_grid(grid: GridSpec, directory: Path, config, command: list[str]) -> float:
    """Runs (or resumes, or keeps) one grid with ``pngail_jax.runner.run``; its wall-clock
    seconds in this call."""
    from pngail_jax import runner

    if grid_complete(directory):
        print(f"\n== {grid.name}: done, kept ({directory})", flush=True)
        return 0.0
    start = time.perf_counter()
    resume = (directory / "config.json").exists()
    if resume:
        print(f"\n== {grid.name}: resuming {directory}", flush=True)
    else:
        print(f"\n== {grid.name}: {grid.demos.description}", flush=True)
    try:
        runner.run(None if resume else config, directory, resume=resume, command=command)
    except runner.RunError as error:
        raise SystemExit(str(error)) from None
    return time.perf_counter() - start


# -- the results page ------------------------------------------------------------------------


def read_curves(directory: Path) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """(method, setting) -> {"steps": int[T], "normalized": float[seeds, T]} from a grid's
    metrics.csv, evaluated iterations only (``report.read_evaluations``)."""
    from pngail_jax.report import read_evaluations

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
    from pngail_jax import stats

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
        "| task | series | final: mean ± s.e. | final: 95% CI | average over the last 10%: "
        "mean ± s.e. | average over all of training: mean ± s.e. | seeds |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for task, series_list in figure.panels.items():
        for series in series_list:
            entry = results[task][series.label]
            lines.append(
                f"| {task} | {series_name(series)} | {_mean_se(entry['final'])} | "
                f"{_interval(entry['final'])} | {_mean_se(entry['late'])} | "
                f"{_mean_se(entry['average'])} | {entry['final']['seeds']} |"
            )
    return [*lines, ""]


def table4_markdown(figure: Figure, results: dict) -> list[str]:
    """Raw returns, ours under both averages (the last 10% of training, and all of it)
    beside the paper's "average reward after training convergence", per method and task."""
    tasks = list(figure.panels)
    paper_column = {task: {"Pendulum-v1": 0, "Ant": 1}[envs.task_family(task)] for task in tasks}
    header = (
        "| method | "
        + " | ".join(
            f"{task}: ours, last 10% | {task}: ours, all of training | {task}: paper (± std)"
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
        normalizer = results[task].get("normalizer")
        ours = _number(normalizer[1], 1) if normalizer else "n/a"
        optimal += [ours, ours, _number(PAPER_TABLE4_OPTIMAL[paper_column[task]], 2)]
    lines.append("| " + " | ".join(optimal) + " |")
    return lines


def weak_expert_notes(out: Path, grids) -> list[str]:
    """One warning line per made demonstration set whose best policy did not beat the random
    one (tiny budgets): its normalised returns run backwards and its confidences mean
    little, which the page must say, not only make_demos' terminal."""
    from pngail_jax.demos import DemonstrationError, load_npz

    notes = []
    for task in dict.fromkeys(g.task for g in grids.values() if g.demos.ratio is not None):
        path = out / "demos" / task / "demos.npz"
        try:
            metadata = load_npz(path).metadata
        except (DemonstrationError, FileNotFoundError):
            continue
        if not metadata.get("optimal_beats_random", True):
            notes.append(
                f"**Warning: {task}'s made expert ({metadata['optimal_return']:.1f}) does not "
                f"beat the random policy ({metadata['random_return']:.1f}).** Its normalised "
                "returns run backwards and its confidences mean little: a larger preset trains "
                "the expert longer."
            )
    return notes


def write_page(out: Path, options: dict, figures: list[Figure], grids, timings: dict) -> Path:
    """``README.md``, one plot per figure and ``results.json`` from the grids' outputs."""
    from pngail_jax.report import json_safe

    loaded = {
        name: (read_curves(out / "grids" / name), read_json(out / "grids" / name / "summary.json"))
        for name in grids
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
            results[figure.name][task]["normalizer"] = config["resolved"].get("normalizer")
    budget = options["budget"]
    lines = [
        f"# The paper's figures at the {budget} preset",
        "",
        f"Preset `{budget}`: {BUDGETS[budget].iterations:,} iterations, {BUDGETS[budget].seeds} "
        "seeds per method. Normalised return: (R - R_random) / (R_optimal - R_random), with "
        "the paper's Table 3 returns for the authors' files and each made set's own measured "
        "random and optimal returns. 'Final' is the last evaluation, 'average over the last "
        "10%' the mean of a seed's evaluations in the last tenth of training (our reading of "
        "the paper's Table 4 'average reward after training convergence'), 'average over all "
        "of training' the mean of every evaluation; mean ± standard error over seeds and a "
        "95% percentile-bootstrap interval of the mean (the paper's own Table 4 numbers are "
        "± its std). "
        + ("**The check preset checks that everything runs; its numbers are not results.**"
           if budget in ("check", "test") else ""),
        "",
        f"Made with `{options['command']}`.",
        "",
        "| grid | task | demonstrations | methods | wall time |",
        "|---|---|---|---|---:|",
    ]  # fmt: skip
    for name, grid in grids.items():
        seconds = timings.get(name)
        wall = "n/a" if seconds is None else f"{seconds / 60:.1f} min"
        lines.append(
            f"| [{name}](grids/{name}/summary.md) | {grid.task} | {grid.demos.description} | "
            f"{', '.join(grid.methods)} | {wall} |"
        )
    lines += ["", *weak_expert_notes(out, grids), ""]
    base = f"python -m experiments.paper --preset {budget}"
    if options.get("released_demos"):
        base += f" --released-demos {options['released_demos']}"
    for figure in figures:
        command = f"{base} --only {figure.name} --envs {','.join(figure.panels)}"
        lines += figure_markdown(figure, results[figure.name], command)
        if figure.name not in ("table1", "table4"):
            plot_figure(out / f"{figure.name}.png", figure, results[figure.name])
    document = {"options": options, "timings": timings, **results}
    write_json(out / "results.json", json_safe(document))
    page = out / "README.md"
    atomic_write_text(page, "\n".join(lines))
    return page


# -- command line ----------------------------------------------------------------------------


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "paper", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument(
        "--only",
        help=f"comma-separated, from {', '.join(FIGURES)} (default: all)",
    )
    parser.add_argument(
        "--envs",
        help=f"comma-separated tasks (default: the paper's six, {', '.join(PAPER_TASKS)}; any "
        f"of {', '.join(envs.ENV_NAMES)})",
    )
    parser.add_argument(
        "--preset",
        "--budget",
        dest="budget",
        choices=(*BUDGETS, *RENAMED_BUDGETS),
        help="check: everything on a CPU, 20 iterations x 2 seeds, a check not a result "
        "(the default); cpu: 500 iterations x 5 seeds (Pendulum-v1 grids in half an hour, "
        "MuJoCo grids in 1.5-2 hours each on a 2-core CPU); paper: 5,000 iterations x 5 "
        "seeds (a GPU); test: the test suite's. --budget is the old name",
    )
    parser.add_argument(
        "--released-demos",
        type=path_argument,
        metavar="DIR",
        help="a folder of the authors' {env}_mixture.npy files (+ _mixture_conf.npy); tasks "
        "without one there use made demonstrations",
    )
    parser.add_argument(
        "--physics",
        choices=envs.PHYSICS,
        help="physics engine of gymnasium's MuJoCo tasks in every grid and make_demos run "
        "(default: c on a CPU, mjx on a GPU or TPU)",
    )
    parser.add_argument("--out", type=path_argument, help="default results/paper-<timestamp>")
    parser.add_argument("--resume", type=path_argument, metavar="DIR", help="continue a run in DIR")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a run of this program already in --out (default: refuse; anything "
        "else there is always refused)",
    )
    compilation.add_arguments(parser)
    args = parser.parse_args(argv)
    note_deprecated(argv, {"--budget": "--preset"})
    if args.resume is not None:
        _check_resume(parser, args)
        return args
    if args.budget in RENAMED_BUDGETS:
        print(
            f"note: preset {args.budget!r} is now {RENAMED_BUDGETS[args.budget]!r} (the sweep's "
            "smoke preset is 300 iterations x 3 seeds)",
            file=sys.stderr,
        )
    args.budget = RENAMED_BUDGETS.get(args.budget, args.budget or "check")
    figures = (  # an empty --only '' is refused, not read as "all" (known_names)
        known_names(parser, args.only, FIGURES, "figure", flag="--only")
        if args.only is not None
        else list(FIGURES)
    )
    args.figures = figures
    args.tasks = (
        known_names(parser, args.envs, envs.ENV_NAMES, "task", flag="--envs")
        if args.envs is not None
        else list(PAPER_TASKS)
    )
    if args.released_demos is not None and not args.released_demos.is_dir():
        parser.error(f"--released-demos {args.released_demos} is not a directory")
    if args.out is None:
        args.out = Path("results") / f"paper-{time.strftime('%Y%m%d-%H%M%S')}"
    claim_output(parser, args.out, "paper", args.overwrite)
    return args


def _check_resume(parser: argparse.ArgumentParser, args) -> None:
    """``--resume DIR`` takes every option from DIR's paper.json: refuses others, and a DIR
    that is not a run of this program."""
    flags = {"only": "--only", "envs": "--envs", "released_demos": "--released-demos"}
    flags |= {"out": "--out", "physics": "--physics", "budget": "--preset"}
    if args.overwrite:
        parser.error("--resume continues a run; --overwrite replaces one: give one")
    given = [flag for name, flag in flags.items() if getattr(args, name) is not None]
    if given:
        parser.error(f"--resume takes its options from the run: drop {given[0]}")
    if not (args.resume / "paper.json").exists():
        parser.error(f"--resume {args.resume}: no paper.json there (not a run of this)")


def command_line(argv) -> list[str]:
    import shlex

    return [shlex.quote(word) for word in (sys.argv[1:] if argv is None else argv)]


def main(argv=None) -> Path:
    args = parse_args(argv)
    out = args.resume if args.resume is not None else args.out
    try:
        with run_lock(out, "paper"):
            if args.resume is None:  # the claim again, now that this process holds the lock
                refusal = output_refusal(out, "paper", args.overwrite)
                if refusal:
                    raise SystemExit(refusal)
            return run_paper(args, argv)
    except RunLocked as error:
        raise SystemExit(f"cannot run: {error}") from None
    except KeyboardInterrupt:
        raise SystemExit(
            f"\ninterrupted: finished grids are kept; --resume {out} continues the plan"
        ) from None


def run_paper(args, argv) -> Path:
    compilation.from_arguments(args)
    out, options = run_options(args, argv)
    budget = BUDGETS[options["budget"]]
    released_dir = Path(options["released_demos"]) if options["released_demos"] else None
    released = released_files(released_dir, options["envs"])
    if args.resume is None:
        options["inputs"] = released_inputs(released)
    else:
        check_paper_inputs(out, options, released)
    figures, grids = plan(options["only"], options["envs"], set(released))
    if not figures:
        raise SystemExit(
            f"none of {', '.join(options['only'])} has a panel on {', '.join(options['envs'])} "
            "(Fig. 4: Ant, Hopper, Pendulum-v1; Fig. 5 / Table 4: Pendulum-v1, Ant; Fig. 6 and "
            "7: Pendulum-v1; Fig. 8 and 10: Ant; Fig. 9: Ant, Pendulum-v1)"
        )
    if args.resume is None:
        prepare_output(out, "paper", args.overwrite)
        write_json(out / "paper.json", options)
        seal(out / PAPER_SEAL, options)
    print(
        f"{len(figures)} figure(s) from {len(grids)} grid(s) on {', '.join(options['envs'])} "
        f"at the {options['budget']} preset; the authors' files for: "
        f"{', '.join(released) or 'none'} -> {out}",
        flush=True,
    )
    physics = options.get("physics")  # absent from runs begun before the flag existed
    demos = demo_paths(grids, out, budget, released, physics)
    timings = run_grids(grids, demos, out, budget, physics, options["command"].split())
    page = write_page(out, options, figures, grids, timings)
    print(f"\nwrote {page}")
    return page


PAPER_SEAL = ".paper.sealed.json"


def released_inputs(released: dict[str, Path]) -> dict[str, dict]:
    """``{role: integrity.file_record}`` of the authors' files (and their confidence files)
    a plan reads, which ``--resume`` checks."""
    from pngail_jax.demos import released_confidence_path
    from pngail_jax.integrity import file_record

    records = {}
    for task, path in released.items():
        records[f"{task} demonstrations"] = file_record(path)
        records[f"{task} confidences"] = file_record(released_confidence_path(path))
    return records


def check_paper_inputs(out: Path, options: dict, released: dict[str, Path]) -> None:
    """Refuses a resume whose authors' files are gone, changed or no longer found (a moved
    folder would otherwise make demonstrations and label the page as before)."""
    from pngail_jax.integrity import changed_inputs

    recorded = options.get("inputs")
    if recorded is None:  # a run from before inputs were recorded
        return
    changes = changed_inputs(recorded)
    missing = sorted(
        role.removesuffix(" demonstrations")
        for role in recorded
        if role.endswith(" demonstrations") and role.removesuffix(" demonstrations") not in released
    )
    if missing and not changes:
        changes = [f"the authors' files for {', '.join(missing)} are no longer found"]
    if changes:
        raise SystemExit(
            f"--resume {out}: {'; '.join(changes)}. The rest of the plan would run on other "
            "data than its start: restore the files (the folder in paper.json's "
            "released_demos), or start a new run"
        )


def run_options(args, argv) -> tuple[Path, dict]:
    """The output directory and the run's options: a resumed run's paper.json (checked
    against its seal and known presets), else the flags'."""
    from pngail_jax.integrity import IntegrityError, sealed_differences

    if args.resume is not None:
        path = args.resume / "paper.json"
        try:
            options = read_json(path, "paper run options")
            changes = sealed_differences(args.resume / PAPER_SEAL, options)
        except IntegrityError as error:
            raise SystemExit(f"--resume {args.resume}: {error}") from None
        if changes:
            raise SystemExit(
                f"--resume {args.resume}: paper.json was changed since the run began ("
                + "; ".join(changes[:5])
                + "): restore it, or start a new run"
            )
        if not isinstance(options, dict) or "budget" not in options:
            raise SystemExit(f"--resume {args.resume}: {path} is not a paper run's options")
        budget = RENAMED_BUDGETS.get(options["budget"], options["budget"])
        if budget not in BUDGETS:
            raise SystemExit(
                f"--resume {args.resume}: {path} names an unknown preset {options['budget']!r} "
                f"(known: {', '.join(BUDGETS)})"
            )
        options["budget"] = budget
        return args.resume, options
    return args.out, {
        "budget": args.budget,
        "only": args.figures,
        "envs": args.tasks,
        "released_demos": None if args.released_demos is None else str(args.released_demos),
        "physics": args.physics,
        "command": " ".join(["python -m experiments.paper", *command_line(argv)]),
    }


def run_grids(grids, demos, out: Path, budget: Budget, physics, command: list[str]) -> dict:
    """Runs (or resumes, or keeps) every grid; each grid's wall-clock seconds over all calls,
    kept in ``out/timings.json``. ``command``: the plan's, recorded in each grid's config."""
    from pngail_jax.demos import load_demonstrations
    from pngail_jax.integrity import IntegrityError

    timings_path = out / "timings.json"
    try:
        timings = read_json(timings_path, "timings record") if timings_path.exists() else {}
    except IntegrityError as error:
        print(f"note: {error}; wall times start again from this call")
        timings = {}
    num_rows = {}  # of each demonstration set, read once, where a grid sizes its split by it
    ran: list[float] = []  # seconds of the grids this call ran
    for index, (name, grid) in enumerate(grids.items()):
        path, scale = demos[grid.demos]
        if grid.unlabelled_fraction != 1 and grid.demos not in num_rows:
            num_rows[grid.demos] = load_demonstrations(path, action_scale=scale).num_rows
        config = grid_config(grid, demos[grid.demos], budget, num_rows.get(grid.demos), physics)
        print(f"\n== grid {index + 1} of {len(grids)}{plan_eta(ran, len(grids) - index)}")
        seconds = run_grid(grid, out / "grids" / name, config, command)
        if seconds:
            ran.append(seconds)
            timings[name] = timings.get(name, 0.0) + seconds
            write_json(timings_path, timings)
    return timings


def plan_eta(seconds: list[float], remaining: int) -> str:
    """', about T left for the plan' from the mean of the grids run so far (grids differ, so a
    rough guide), or '' before any has run."""
    from pngail_jax.runner import format_seconds

    if not seconds:
        return ""
    return f", about {format_seconds(remaining * sum(seconds) / len(seconds))} left for the plan"


if __name__ == "__main__":
    main()
