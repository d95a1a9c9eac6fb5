"""Train TRPO (or PPO, ``--learner ppo``) on an environment's true reward, several seeds in
one compiled program.

    python -m experiments.train_rl --env Pendulum-v1 --iterations 100 --seeds 3 --out runs/trpo

Shows progress every ``--eval-every`` iterations (iteration, evaluation and training returns,
steps/s), then writes to ``--out``: ``config.json``, ``metrics.csv`` (one row per seed and
iteration), ``learning_curve.png`` and the policies (``policy.json`` + ``policy_params/``),
which ``pngail_jax.load_policy(out)`` loads without this code. The flags become a
``TrainRLConfig`` for the job, ``pngail_jax.jobs.train_rl.train_rl``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pngail_jax.config.budget import check_eval_interval
from pngail_jax.config.validation import ConfigError
from pngail_jax.jobs.errors import RunError
from pngail_jax.jobs.train_rl import PROGRAM, TrainRLConfig, flat_document, train_rl
from pngail_jax.programs import flags
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    add_compile_cache_flags,
    check_env,
    check_positive,
    claim_output,
    config_from,
    interrupted,
    note_deprecated,
    path_argument,
    resumed_args,
    signals_stop_at_a_checkpoint,
    use_compile_cache,
)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        "train_rl", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    add = parser.add_argument
    add("--env", default="Pendulum-v1", help=ENV_HELP)
    add("--iterations", type=int, default=100, help="policy iterations (rollout + update)")
    add("--seeds", type=int, default=3, help="seeds, trained side by side")
    add("--seed", type=int, default=0, help="base PRNG seed")
    add(
        "--out",
        type=path_argument,
        default=None,
        help="output directory (default runs/<learner>-<env>-<timestamp>)",
    )
    add(
        "--overwrite",
        action="store_true",
        help="replace a trained policy already in --out (default: refuse)",
    )
    add(
        "--resume",
        type=path_argument,
        metavar="DIR",
        help="continue DIR's interrupted run from its last checkpoint, with its own flags "
        "(default: a new run)",
    )
    add(
        "--truncation-as-terminal",
        action="store_true",
        help="the reference's GAE: no bootstrapping through time limits",
    )
    add("--fast-solver", action="store_true", help="deprecated: the same as --solver fast")
    flags.add_learner_flags(parser)
    flags.add_settings_flags(parser)
    add_compile_cache_flags(parser)
    return parser


def parse_args(argv=None) -> argparse.Namespace:
    """The checked flags of ``argv``: of a new run (its ``--out`` claimed), or of the run that
    ``--resume DIR`` continues (its own flags, read from its config.json)."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    if args.resume is not None:
        return resumed_args(
            parser, args, argv, program=PROGRAM, finished="policy.json",
            job=f"pngail_jax.jobs.{PROGRAM}.train_rl", check=_check,
            read_argv=lambda document: flat_document(document)["argv"],  # any layout's
        )  # fmt: skip
    note_deprecated(argv, {"--fast-solver": "--solver fast"})
    _check(parser, args)
    if args.out is None:
        args.out = Path("runs") / f"{args.learner.name}-{args.env}-{time.strftime('%Y%m%d-%H%M%S')}"
    claim_output(parser, args.out, "train_rl", args.overwrite)
    args.argv = argv
    return args


def _check(parser, args) -> None:
    check_env(parser, args.env)
    if args.fast_solver:
        if args.solver not in (None, "fast"):
            parser.error("--fast-solver and --solver disagree")
        args.solver = "fast"
    check_positive(parser, args, ("iterations", "seeds"))
    args.settings = flags.settings_from_flags(parser, args, args.env)
    args.learner = flags.learner_from_flags(parser, args)
    try:
        check_eval_interval(args.iterations, args.settings.eval_every, "--eval-every")
    except ConfigError as error:
        parser.error(error.named("--iterations"))
    try:
        args.learner.check_batch(args.settings.rollout_config(args.iterations))
    except ValueError as error:
        parser.error(str(error))


def main(argv=None) -> None:
    args = parse_args(argv)
    use_compile_cache(args)
    try:
        with signals_stop_at_a_checkpoint():
            train_rl(
                config_from(TrainRLConfig, args),
                args.out,
                overwrite=args.overwrite,
                resume=args.resume is not None,
                command=args.argv,
            )
    except RunError as error:
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        raise SystemExit(interrupted(args.out, "blocks")) from None
