"""Reproduce the paper's figures and tables: the grids behind them and one results page.

    python -m experiments.paper --preset check     # all of it on a 2-core CPU (under an hour)
    python -m experiments.paper --preset paper --released-demos data/released   # a GPU
    python -m experiments.paper --preset gpu --throughput gpu_check.json ...    # its wall time
    python -m experiments.paper --only fig2,table1 --envs Hopper,Pendulum-v1
    python -m experiments.paper --resume results/paper-20261123-120000
    python -m experiments.paper --page results/paper-20261123-120000   # the page so far

Each figure is a set of ``experiments.sweep`` grids, one compiled program per task and
demonstration set (a task's Fig. 2 and Fig. 3 share one grid of the seven methods). The
demonstrations come from ``--released-demos DIR`` where it holds the authors' file for a task
(``Hopper-v2_mixture.npy`` ...; each file's known action scale applied), else from one
demonstration making (``pngail_jax.jobs.make_demos``, what ``experiments.make_demos`` runs) per
task, whose trajectories are mixed at each ratio a figure
asks for. Writes ``DIR/README.md`` (every figure's plot and table beside the paper's numbers,
each with the command that makes it alone), ``DIR/<figure>.png``, ``DIR/results.json``,
``DIR/demos/`` and one sweep directory per grid in ``DIR/grids/``. An interrupted run continues
with ``--resume DIR``: finished grids are kept, an unfinished one resumes from its checkpoint.
``--page DIR`` writes the page of what DIR's plan has run so far (while it runs, or between
``--resume`` calls) into ``--out``, running nothing.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from pngail_jax import envs
from pngail_jax.config.learner import LEARNERS
from pngail_jax.jobs.errors import RunError
from pngail_jax.paper.estimate import read_throughput
from pngail_jax.paper.grids import grid_config, plan_eta
from pngail_jax.paper.page import weak_expert_notes
from pngail_jax.paper.plan import (
    BUDGETS,
    FIG2_METHODS,
    FIGURES,
    PAPER_TASKS,
    RENAMED_BUDGETS,
    SEVEN_METHODS,
    DemoSet,
    main_grid,
    plan,
)
from pngail_jax.paper.run import (
    check_paper_inputs,
    page_so_far,
    paper_options,
    released_inputs,
    run_paper,
)
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    add_compile_cache_flags,
    claim_output,
    current_spellings,
    invoked_as,
    known_names,
    note_deprecated,
    path_argument,
    signals_stop_at_a_checkpoint,
    use_compile_cache,
)

# Names of the library's paper modules that this program's users (and tests) read from it.
__all__ = [
    "BUDGETS", "FIG2_METHODS", "FIGURES", "SEVEN_METHODS", "DemoSet", "check_paper_inputs",
    "envs", "grid_config", "main", "main_grid", "parse_args", "plan", "plan_eta",
    "released_inputs", "weak_expert_notes",
]  # fmt: skip

# -- command line ----------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
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
        "seeds (a GPU); gpu: the paper's budget in longer chunks, with an estimate of its "
        "wall time from --throughput; test: the test suite's. --budget is the old name",
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
    parser.add_argument(
        "--learner",
        choices=LEARNERS,
        help="the policy learner of every grid and make_demos run: trpo (the paper's) or ppo "
        "(docs/ppo.md) (default trpo)",
    )
    parser.add_argument(
        "--demo-learner",
        choices=LEARNERS,
        help="the policy learner of the make_demos runs alone (default: --learner's): a "
        "stronger made expert at the preset's budget, the grids' learner unchanged",
    )
    parser.add_argument(
        "--throughput",
        type=path_argument,
        metavar="FILE",
        help="a benchmark's rows measured on this machine (benchmarks/gpu_check.py --json, or "
        "benchmarks/grid_throughput.py --json): the plan's wall time is estimated from them "
        "before it starts (also with --resume, for what is left)",
    )
    add_run_folder_flags(parser)
    add_compile_cache_flags(parser)
    return parser


def add_run_folder_flags(parser: argparse.ArgumentParser) -> None:
    """Where the plan runs and what it starts from: --adopt, --out, --resume, --overwrite."""
    parser.add_argument(
        "--adopt",
        action="append",
        type=path_argument,
        metavar="DIR",
        help="repeatable: a finished experiments.sweep run to keep as the plan's grid whose "
        "config it is (up to --chunk-iterations), instead of running that grid again; with "
        "--resume too (default: none)",
    )
    add_allow_unsealed(parser.add_argument, "--adopt a sweep, or resume a plan's grid,")
    parser.add_argument("--out", type=path_argument, help="default results/paper-<timestamp>")
    parser.add_argument("--resume", type=path_argument, metavar="DIR", help="continue a run in DIR")
    parser.add_argument(
        "--page",
        type=path_argument,
        metavar="DIR",
        help="write the results page of what the plan in DIR has run so far into --out "
        "(default results/paper-page-<timestamp>), running nothing: a grid in progress at the "
        "iteration it reached, one not started left out, each said",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a run of this program already in --out (default: refuse; anything "
        "else there is always refused)",
    )


def parse_args(argv=None) -> argparse.Namespace:
    """The checked flags of ``argv`` (a resumed run's come from its paper.json later)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    note_deprecated(argv, DEPRECATED_FLAGS)
    if args.page is not None:
        _check_page(parser, args)
        return args
    if args.throughput is not None:
        _check_throughput(parser, args.throughput)
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


# The flags that set a plan's options (paper.json): --resume and --page read them from the run.
PLAN_FLAGS = {
    "only": "--only", "envs": "--envs", "released_demos": "--released-demos",
    "physics": "--physics", "budget": "--preset", "learner": "--learner",
    "demo_learner": "--demo-learner",
}  # fmt: skip


def _check_resume(parser: argparse.ArgumentParser, args) -> None:
    """``--resume DIR`` takes every option from DIR's paper.json: refuses others, and a DIR
    that is not a run of this program."""
    flags = PLAN_FLAGS | {"out": "--out"}
    if args.overwrite:
        parser.error("--resume continues a run; --overwrite replaces one: give one")
    given = [flag for name, flag in flags.items() if getattr(args, name) is not None]
    if given:
        parser.error(f"--resume takes its options from the run: drop {given[0]}")
    if not (args.resume / "paper.json").exists():
        parser.error(f"--resume {args.resume}: no paper.json there (not a run of this)")


def _check_throughput(parser: argparse.ArgumentParser, path: Path) -> None:
    """``--throughput FILE`` is read and each number the estimate reads checked now, before
    an output folder is claimed or made (``paper.estimate.read_throughput``): a bad row is one
    line naming the file, the row, the field and its value."""
    try:
        read_throughput(path)
    except RunError as error:
        parser.error(str(error))


def _check_page(parser: argparse.ArgumentParser, args) -> None:
    """``--page DIR`` reads the plan's options from DIR: takes only --out and --overwrite."""
    flags = PLAN_FLAGS | {"resume": "--resume", "adopt": "--adopt", "throughput": "--throughput"}
    given = [flag for name, flag in flags.items() if getattr(args, name) is not None]
    if given:
        parser.error(f"--page writes the page of the plan in DIR as it is: drop {given[0]}")
    if args.out is None:
        args.out = Path("results") / f"paper-page-{time.strftime('%Y%m%d-%H%M%S')}"
    claim_output(parser, args.out, "paper-page", args.overwrite)


DEPRECATED_FLAGS = {"--budget": "--preset"}


def command_line(argv) -> list[str]:
    """The command's words, quoted for a shell, deprecated flags in their current spelling."""

    words = current_spellings(sys.argv[1:] if argv is None else argv, DEPRECATED_FLAGS)
    for index, word in enumerate(words):  # a renamed preset by its name now
        flag, equals, value = word.partition("=")
        if equals and flag == "--preset" and value in RENAMED_BUDGETS:
            words[index] = f"--preset={RENAMED_BUDGETS[value]}"
        elif index and words[index - 1] == "--preset" and word in RENAMED_BUDGETS:
            words[index] = RENAMED_BUDGETS[word]
    return [shlex.quote(word) for word in words]


def main(argv=None) -> Path:
    args = parse_args(argv)
    if args.page is not None:
        try:
            return page_so_far(args.page, args.out, overwrite=args.overwrite)
        except RunError as error:
            raise SystemExit(str(error)) from None
    resume = args.resume is not None
    out = args.resume if resume else args.out
    use_compile_cache(args)
    options = None
    if not resume:
        options = paper_options(
            args.budget,
            args.figures,
            args.tasks,
            args.released_demos,
            args.physics,
            " ".join([*invoked_as("paper"), *command_line(argv)]),
            args.learner or "trpo",
            args.demo_learner,
        )
    try:
        with signals_stop_at_a_checkpoint():
            return run_paper(
                options,
                out,
                resume=resume,
                overwrite=args.overwrite,
                adopt=args.adopt or (),
                allow_unsealed=args.allow_unsealed,
                throughput=args.throughput,
            )
    except RunError as error:  # a grid's or a demonstration making's refusal, one line
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        raise SystemExit(
            f"\ninterrupted: finished grids are kept; --resume {out} continues the plan"
        ) from None
