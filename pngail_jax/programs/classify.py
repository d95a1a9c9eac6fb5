"""Table 1: how well SC and BSC recover hidden confidences, all seeds x methods in one program.

    python -m experiments.classify --demos data/released/Pendulum-v1_mixture.npy

Reads raw [s, a] rows (no environment needed), draws per seed a split of ``--num-demos`` rows
with ``--label-ratio`` of them labelled, trains each classifier and prints MAE / RMSE over the
unlabelled rows (mean +- population std over seeds), against the confidences before noise.
Only rows that a ``.npz`` file's ``labelled`` mask allows are labelled. The flags become a
``ClassifyConfig`` for the job, ``pngail_jax.jobs.classify.classify``.
"""

from __future__ import annotations

import argparse
import math

from pngail_jax.jobs.classify import METHODS, ClassifyConfig, classify
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    check_json_output,
    check_positive,
    config_from,
    known_names,
    note_deprecated,
    path_argument,
)


def build_parser() -> argparse.ArgumentParser:
    """The data flags (which rows, how they are read), then the split and training ones."""
    parser = ArgumentParser(
        "classify", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument(
        "--demos",
        type=path_argument,
        required=True,
        help="*_mixture.npy (released layout) or our .npz",
    )
    parser.add_argument(
        "--conf",
        type=path_argument,
        default=None,
        help="confidence file (default: the *_mixture_conf.npy sibling)",
    )
    parser.add_argument(
        "--action-scale",
        type=float,
        default=None,
        help="multiply stored actions (default: an authors' file's known scale, 2 for their "
        "Pendulum file; else 1)",
    )
    parser.add_argument(
        "--env",
        default=None,
        help="the environment of a file of rows that is not an authors' one: its observation "
        "and action sizes split the rows (default: none, an authors' file knows its own)",
    )
    parser.add_argument(
        "--num-demos",
        "--traj-size",
        dest="num_demos",
        type=int,
        default=None,
        help="rows per seed, n_c + n_u (default: all)",
    )
    add_training_flags(parser)
    return parser


def add_training_flags(parser: argparse.ArgumentParser) -> None:
    """The split (rows, labelled share, noise), the classifiers and their training, the output."""
    parser.add_argument("--label-ratio", type=float, default=0.2, help="labelled share, n_c")
    parser.add_argument("--noise", type=float, default=0.0, help="confidence noise std")
    parser.add_argument(
        "--classifiers", "--methods", dest="classifiers", default="sc,bsc", help="comma-separated"
    )
    parser.add_argument("--seeds", type=int, default=5, help="seeds (splits and inits)")
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument(
        "--classifier-steps",
        "--steps",
        dest="classifier_steps",
        type=int,
        default=25_000,
        help="classifier training steps",
    )
    parser.add_argument(
        "--batch-size",
        type=int,
        default=1,
        help="labelled rows per step (unlabelled: this x n_u / n_c)",
    )
    parser.add_argument(
        "--bsc-eps", "--eps", dest="bsc_eps", type=float, default=0.01, help="BSC clip"
    )
    parser.add_argument(
        "--json", type=path_argument, default=None, help="also write the results here"
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an existing --json file (default: refuse)"
    )


def parse_args(argv=None) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv)
    note_deprecated(argv, DEPRECATED_FLAGS)
    check_arguments(parser, args)
    return args


def check_arguments(parser: argparse.ArgumentParser, args) -> None:
    """Exits through ``parser.error`` naming the first flag with a bad value."""
    args.classifiers = known_names(parser, args.classifiers, METHODS, "classifier")
    if not 0 < args.label_ratio < 1:  # also refuses nan
        parser.error(f"--label-ratio must be in (0, 1), got {args.label_ratio}")
    check_positive(parser, args, ("seeds", "classifier_steps", "batch_size"))
    if args.num_demos is not None and args.num_demos < 2:
        parser.error(
            f"--num-demos must be at least 2 (one labelled and one unlabelled row), "
            f"got {args.num_demos}"
        )
    for flag, value, minimum in (
        ("--noise", args.noise, ">= 0"),
        ("--bsc-eps", args.bsc_eps, "> 0"),
        ("--action-scale", 1.0 if args.action_scale is None else args.action_scale, "> 0"),
    ):
        in_range = value >= 0 if minimum == ">= 0" else value > 0
        if not (math.isfinite(value) and in_range):
            parser.error(f"{flag} must be a finite number {minimum}, got {value}")
    check_json_output(parser, args.json, args.overwrite)


# The sweep's names for the same things (the old spellings still work, with a note).
DEPRECATED_FLAGS = {
    "--steps": "--classifier-steps",
    "--eps": "--bsc-eps",
    "--traj-size": "--num-demos",
    "--methods": "--classifiers",
}


def main(argv=None) -> dict:
    """Trains the classifiers of the flags (every seed of each in one program), prints their
    errors (Table 1) and BSC risk variances (Table 5), and returns the summary."""
    args = parse_args(argv)
    try:
        return classify(config_from(ClassifyConfig, args), args.json)
    except RunError as error:
        raise SystemExit(str(error)) from None
