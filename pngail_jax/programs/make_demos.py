"""Generate imperfect demonstrations: an optimal and an intermediate policy (TRPO, or PPO
with ``--learner ppo``), mixed.

    python -m experiments.make_demos --env Pendulum-v1 --out demos/pendulum

The flags of ``pngail_jax.jobs.make_demos.MakeDemosConfig`` and one call of
``make_demonstrations``, which says what is made and how: a learner's run on the true reward
whose evaluated checkpoints are kept (``checkpoints/iter_XXXX/``), the best one as the optimal
policy and an earlier one near ``--intermediate-target`` as the intermediate one, the random
and optimal returns measured (Table 3), and ``--num-trajectories`` deterministic episodes at
the optimal:intermediate ``--ratio`` labelled with their normalised returns in ``demos.npz``.

``demos.npz`` is written last and atomically (a temporary sibling renamed onto it), so its
presence means the run finished; a second run into the same ``--out`` refuses to replace it
unless ``--overwrite`` is given (the sweep makes its own cache with the library's
``make_demonstrations``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pngail_jax.config.validation import ConfigError
from pngail_jax.jobs.errors import RunError
from pngail_jax.jobs.make_demos import MakeDemosConfig, make_demonstrations
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
    path_argument,
    use_compile_cache,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "make_demos", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("--env", default="Pendulum-v1", help=ENV_HELP)
    parser.add_argument(
        "--out", type=path_argument, required=True, help="output directory (required)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run's demos.npz, normalizer.json and checkpoints in --out "
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
    args = parser.parse_args(argv)
    claim_output(parser, args.out, "make_demos", args.overwrite)
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
    return args


def main(argv=None) -> Path:
    args = parse_args(argv)
    use_compile_cache(args)
    try:
        return make_demonstrations(args.config, args.out, overwrite=args.overwrite)
    except RunError as error:
        raise SystemExit(str(error)) from None
