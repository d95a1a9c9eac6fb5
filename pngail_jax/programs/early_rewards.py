"""Where each method's reward points early in training, on the authors' Pendulum-v1 set: the
flags of ``pngail_jax.jobs.early_rewards`` (GAIL, PN-GAIL\\PN, PN-GAIL and PN-GAIL with 99% of
the rows labelled side by side; every ``--every`` iterations the evaluation return and the
policy reward the discriminator gives the optimal rows, the intermediate ones and the agent).

    python -m experiments.early_rewards --demos data/released/Pendulum-v1_mixture.npy

writes ``early_rewards.json`` (``--out``) and prints a markdown table.
"""

from __future__ import annotations

from pathlib import Path

from pngail_jax.jobs.early_rewards import VARIANTS, EarlyRewardsConfig, early_rewards
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs.cli import ArgumentParser, HelpFormatter, path_argument

__all__ = ["VARIANTS", "main", "parse_args"]


def parse_args(argv=None):
    parser = ArgumentParser("early_rewards", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument(
        "--demos", type=path_argument, required=True, help="Pendulum-v1_mixture.npy"
    )
    parser.add_argument("--seeds", type=int, default=3, help="seeds per variant")
    parser.add_argument("--iterations", type=int, default=150, help="TRPO iterations")
    parser.add_argument("--every", type=int, default=10, help="iterations between readings")
    parser.add_argument(
        "--classifier-steps", type=int, default=25_000, help="confidence classifier steps"
    )
    parser.add_argument(
        "--out", type=path_argument, default=Path("early_rewards.json"), help="JSON file"
    )
    return parser.parse_args(argv)  # the job's config checks the values, the job the --out


def main(argv=None) -> dict:
    """Runs the job of the flags and returns its readings."""
    args = parse_args(argv)
    try:
        config = EarlyRewardsConfig(
            str(args.demos), args.seeds, args.iterations, args.every, args.classifier_steps
        )
        return early_rewards(config, args.out)
    except (RunError, ValueError) as error:
        raise SystemExit(f"early_rewards: {error}") from None
