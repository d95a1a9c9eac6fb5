"""Generate imperfect demonstrations: an optimal and an intermediate policy (TRPO, or PPO
with ``--learner ppo``), mixed.

    python -m experiments.make_demos --env Pendulum-v1 --out demos/pendulum

The flags of ``pngail_jax.jobs.make_demos.MakeDemosConfig`` and one call of
``make_demonstrations``, which says what is made and how: a learner's run on the true reward
whose evaluated checkpoints are kept (``checkpoints/iter_XXXX/``), the best one as the optimal
policy and an earlier one near ``--intermediate-target`` as the intermediate one, the random
and optimal returns measured (Table 3), and ``--num-trajectories`` deterministic episodes at
the optimal:intermediate ``--ratio`` labelled with their normalised returns in ``demos.npz``.

``config.json`` (sealed, with the flags) is written first and ``demos.npz`` last and
atomically (a temporary sibling renamed onto it), so its presence means the run finished; a
second run into the same ``--out`` refuses to replace it unless ``--overwrite`` is given (the
sweep makes its own cache with the library's ``make_demonstrations``).

A run cut short (Ctrl-C, a SIGTERM, a lost machine) keeps the learner's whole state after
every block (``training/``, the last two) and continues from the last one with its own flags:

    python -m experiments.make_demos --resume demos/pendulum

(``--resume DIR`` takes no other flag but the compilation cache's), to the demonstrations an
uninterrupted run makes; ``training/`` is removed when ``demos.npz`` is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pngail_jax.config.validation import ConfigError
from pngail_jax.jobs.errors import RunError
from pngail_jax.jobs.make_demos import DEMOS_FILE, PROGRAM, MakeDemosConfig, make_demonstrations
from pngail_jax.programs import flags
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    add_compile_cache_flags,
    check_env,
    check_finite,
    check_positive,
    claim_output,
    config_from,
    interrupted,
    path_argument,
    resumed_args,
    signals_stop_at_a_checkpoint,
    use_compile_cache,
)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        PROGRAM, description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("--env", default="Pendulum-v1", help=ENV_HELP)
    parser.add_argument(
        "--out", type=path_argument, help="output directory (required for a new run)"
    )
    parser.add_argument(
        "--resume",
        type=path_argument,
        metavar="DIR",
        help="continue DIR's interrupted run from its last checkpoint, with its own flags "
        "(default: a new run)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run in --out (its demos.npz, config.json, checkpoints ...) "
        "(default: refuse)",
    )
    parser.add_argument("--iterations", type=int, default=150, help="policy iterations")
    parser.add_argument("--seeds", type=int, default=3, help="policy seeds; the best is optimal")
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument("--ratio", default="1:4", help="optimal:intermediate trajectories")
    parser.add_argument(
        "--num-trajectories", type=int, default=5, help="trajectories in the mixture"
    )
    parser.add_argument(
        "--intermediate-target",
        type=float,
        default=0.45,
        help="normalised return the intermediate policy is picked near",
    )
    parser.add_argument(
        "--measure-episodes",
        type=int,
        default=64,
        help="episodes for the random and optimal returns",
    )
    flags.add_learner_flags(parser)
    flags.add_settings_flags(parser)
    # Checkpoints are kept at every evaluation, and the intermediate policy is picked among
    # them: finer than the table's evaluation interval by default.
    parser.set_defaults(eval_every=10)
    add_compile_cache_flags(parser)
    return parser


def parse_args(argv=None) -> argparse.Namespace:
    """The checked flags of ``argv``, with ``config`` (a ``MakeDemosConfig``): of a new run
    (its ``--out`` claimed), or of the run that ``--resume DIR`` continues (its own flags,
    read from its config.json)."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    if args.resume is not None:
        return resumed_args(
            parser, args, argv, program=PROGRAM, finished=DEMOS_FILE,
            job=f"pngail_jax.jobs.{PROGRAM}.make_demonstrations", check=_check,
        )  # fmt: skip
    if args.out is None:
        parser.error("the following arguments are required: --out (or --resume DIR)")
    claim_output(parser, args.out, PROGRAM, args.overwrite)
    _check(parser, args)
    args.argv = argv
    return args


def _check(parser, args) -> None:
    """Checks the flags and sets ``args.config`` (exits through ``parser.error``)."""
    check_env(parser, args.env)
    check_positive(parser, args, ("iterations", "seeds", "num_trajectories", "measure_episodes"))
    check_finite(parser, args, ("intermediate_target",))
    args.settings = flags.settings_from_flags(parser, args, args.env)
    args.learner = flags.learner_from_flags(parser, args)
    try:
        args.config = config_from(MakeDemosConfig, args)
    except ConfigError as error:  # every field of MakeDemosConfig is the flag of its name
        parser.error(error.named("--" + error.field.replace("_", "-")))
    except ValueError as error:
        parser.error(str(error))


def main(argv=None) -> Path:
    args = parse_args(argv)
    use_compile_cache(args)
    try:
        with signals_stop_at_a_checkpoint():
            return make_demonstrations(
                args.config,
                args.out,
                overwrite=args.overwrite,
                resume=args.resume is not None,
                command=args.argv,
            )
    except RunError as error:
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        raise SystemExit(interrupted(args.out, "blocks")) from None
