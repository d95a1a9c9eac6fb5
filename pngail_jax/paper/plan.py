"""The paper's experiments as data: its methods, figures and tables (the numbers it reports),
the budgets (iterations, seeds, run settings per task kind), and the plan: each figure's
builder adds the grids it reads (``GridSpec``: a task, a demonstration set, methods, label
ratios, noise) to a ``Planner``, so a grid two figures share is run once."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from pngail_jax import envs
from pngail_jax.adversarial.methods import required_phases

FIG2_METHODS = ("gail", "2iwil", "icgail", "wgail", "pngail")
FIG3_METHODS = ("pngail", "pngail-no-bsc", "pngail-no-pn")
SEVEN_METHODS = ("gail", "2iwil", "icgail", "wgail", "pngail", "pngail-no-bsc", "pngail-no-pn")
# The paper's six tasks: its MuJoCo tasks as gymnasium's -v4 (gym -v2's model files and
# observations). Figures name tasks by family (``envs.task_family``), so Brax's variants
# (``--envs Hopper``) fill the same panels.
MUJOCO_TASKS = tuple(task for task in envs.GYM_TASKS if task.endswith("-v4"))  # the paper's
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
    ``RunSettings`` fields per task kind over the task's row of ``pngail_jax.config.settings``."""

    iterations: int
    seeds: int
    chunk_iterations: int
    classifier_steps: int | None  # None: the task's (25,000; 50,000 on Walker2d)
    demo_iterations: dict[str, int]  # per task kind: "pendulum" / "mujoco"
    demo_seeds: int
    measure_episodes: int
    settings: dict[str, dict[str, int]]  # per task kind
    demo_settings: dict[str, dict[str, int]]
    # Solver caps of a task's grids and demonstration runs ("fast" or "I/L", as --solver
    # takes them); a task not named keeps its row's (gymnasium's own on the -v4 tasks).
    solvers: dict[str, str] = dataclasses.field(default_factory=dict)
    # The appendix baselines' training phases: "codebase" (their codebases' sizes) or "check"
    # (pngail_jax.config.budget.CHECK_PHASE_SIZES), RunConfig.phase_sizes of every grid.
    phase_sizes: str = "codebase"

    def settings_for(self, task: str, physics: str | None, demos: bool = False):
        """The ``RunSettings`` of ``task``'s grids (``demos``: of its demonstration making,
        which evaluates every 10 iterations unless the budget says otherwise) on
        ``physics`` (gymnasium's MuJoCo tasks only; None: the platform's engine)."""
        from pngail_jax.config.settings import parse_solver, settings_for

        kind = task_kind(task)
        fields = {"eval_every": 10, **self.demo_settings[kind]} if demos else self.settings[kind]
        if task in self.solvers:
            fields = {**parse_solver(self.solvers[task]), **fields}
        engine = physics if task in envs.GYM_TASKS else None
        return settings_for(task, **fields, physics=engine)


NO_SETTINGS = {"pendulum": {}, "mujoco": {}}  # every task's own row
PAPER_BUDGET = Budget(
    iterations=5_000,
    seeds=5,
    chunk_iterations=250,
    classifier_steps=None,
    demo_iterations={"pendulum": 300, "mujoco": 2_000},
    demo_seeds=3,
    measure_episodes=64,
    settings=NO_SETTINGS,
    demo_settings=NO_SETTINGS,
)
# The accelerator's solver caps per -v4 task: the fewest caps (of the fast ones, 4 / 16 and
# gymnasium's own) whose TRPO learned not worse than gymnasium's own solver, judged on the
# task's own physics over 5 seeds x 2 M steps (docs/performance.md, "The solver caps on
# gymnasium's tasks"). Fewer caps are cheaper on MJX, where every env of a batch waits for the
# slowest one's solver; the C engine on a CPU keeps gymnasium's own unless a preset says.
GPU_SOLVERS = {
    "Swimmer-v4": "fast",
    "HalfCheetah-v4": "4/16",
}
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
        phase_sizes="check",
    ),
    # The paper's budget: 5,000 TRPO iterations of about 5,000 steps, 5 seeds (a GPU).
    "paper": PAPER_BUDGET,
    # The paper's budget on an accelerator: its iterations and seeds, each task's own row of
    # the settings table (25 envs x 200 steps, TRPO's one value pass: the reference's), the
    # solver caps that learned not worse (GPU_SOLVERS), longer chunks (fewer round trips to
    # the host), and with --throughput an estimate of the wall time before it starts.
    "gpu": dataclasses.replace(PAPER_BUDGET, chunk_iterations=500, solvers=GPU_SOLVERS),
    # A tenth of the paper's budget (2.5 M steps per run): Pendulum-v1 grids in about half
    # an hour each on a 2-core CPU, the MuJoCo grids of the authors' files on the C engine in
    # 1.5-2 hours each (Hopper-v4: 122 minutes beside other jobs; docs/results/tenth-budget.md).
    "cpu": dataclasses.replace(
        PAPER_BUDGET,
        iterations=500,
        chunk_iterations=100,
        demo_iterations={"pendulum": 150, "mujoco": 300},
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
        phase_sizes="check",
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
