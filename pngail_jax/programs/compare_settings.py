"""What a run setting does to learning: TRPO on the true reward, arms x the same seeds.

    python -m experiments.compare_settings --env Hopper --arms reference-fast,table \\
        --seeds 5 --iterations 400 --out runs/settings/Hopper

Each arm is one ``experiments.train_rl`` run into ``OUT/<arm>/`` (skipped when that directory
already holds a finished run, so an interrupted comparison continues where it stopped), all
with the same seeds, Fisher form and iteration count. Then every arm's final policies are
evaluated by one protocol: ``--num-eval-episodes`` deterministic episodes from the same reset keys
on the task's own MJX solver and on the fast one, so a policy trained on the fast physics is
also judged on the accurate one. Writes ``comparison.json``, ``comparison.md`` and
``comparison.png`` (evaluation return vs environment steps, mean and standard error band).

``comparison.json`` is written last (each output atomically), so it marks a finished
comparison: running into the same ``--out`` again refuses unless ``--overwrite`` is given
(which rewrites the comparison; finished arms are still reused).

The verdict follows docs/performance.md: an arm is "not worse" than ``--baseline`` when its
mean final return is at least the baseline's mean minus one standard error.
"""

from __future__ import annotations

import argparse

from pngail_jax.jobs.compare_settings import (
    ARMS,
    COMPARISON_FILE,
    CompareSettingsConfig,
    arm_flags,
    compare_settings,
)
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    check_env,
    check_positive,
    claim_output,
    config_from,
    known_names,
    note_deprecated,
    path_argument,
)


def build_parser() -> argparse.ArgumentParser:
    """The program's flags (``parse_args`` checks them)."""
    parser = ArgumentParser(
        "compare_settings",
        description=__doc__.split("\n\n")[0],
        epilog="arms:\n"
        + "\n".join(f"  {name:18s} train_rl {' '.join(arm_flags(name))}" for name in ARMS),
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--env", required=True, help=ENV_HELP)
    parser.add_argument("--arms", default="reference-fast,table", help="comma-separated")
    parser.add_argument("--baseline", help="the arm others are judged against (default: first)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per arm (the same in each)")
    parser.add_argument("--iterations", type=int, default=400, help="TRPO iterations per arm")
    parser.add_argument("--eval-every", type=int, default=50, help="iterations between evaluations")
    parser.add_argument(
        "--num-eval-episodes",
        "--eval-episodes",
        dest="num_eval_episodes",
        type=int,
        default=32,
        help="of the final evaluation",
    )
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument(
        "--out", type=path_argument, required=True, help="output directory (required)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="rewrite a finished comparison in --out (its finished arms are reused; "
        "default: refuse)",
    )
    return parser


def parse_args(argv=None) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv)
    note_deprecated(argv, {"--eval-episodes": "--num-eval-episodes"})
    # Running into an unfinished comparison again is its resume (finished arms are reused).
    unfinished = not (args.out / COMPARISON_FILE).exists()
    claim_output(parser, args.out, "compare_settings", args.overwrite or unfinished)
    check_env(parser, args.env)
    args.arms = known_names(parser, args.arms, list(ARMS), "arm", flag="--arms")
    if args.env == "Pendulum-v1" and any("--solver" in ARMS[arm] for arm in args.arms):
        parser.error("Pendulum-v1 has no MJX solver: choose arms without --solver")
    args.baseline = args.baseline or args.arms[0]
    if args.baseline not in args.arms:
        parser.error(f"--baseline {args.baseline!r} is not among --arms")
    check_positive(parser, args, ("seeds", "iterations", "eval_every", "num_eval_episodes"))
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    config = config_from(CompareSettingsConfig, args)
    try:
        return compare_settings(config, args.out, overwrite=args.overwrite, command=argv)
    except RunError as error:
        raise SystemExit(str(error)) from None
