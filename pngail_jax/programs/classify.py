"""Table 1: how well SC and BSC recover hidden confidences, all seeds x methods in one program.

    python -m experiments.classify --demos data/released/Pendulum-v1_mixture.npy

Reads raw [s, a] rows (no environment needed), draws per seed a split of ``--num-demos`` rows
with ``--label-ratio`` of them labelled, trains each classifier and prints MAE / RMSE over the
unlabelled rows (mean +- population std over seeds), against the confidences before noise.
Only rows that a ``.npz`` file's ``labelled`` mask allows are labelled.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from pngail_jax.confidence import ClassifierConfig, ClassifierSpec, split_and_train
from pngail_jax.demos import (
    DemonstrationError,
    Demonstrations,
    action_scale_note,
    load_demonstrations,
)
from pngail_jax.integrity import write_json
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    check_positive,
    known_names,
    note_deprecated,
    path_argument,
)
from pngail_jax.report import json_safe

METHODS = {"sc": ClassifierSpec.sc, "bsc": ClassifierSpec.bsc}


def build_parser() -> argparse.ArgumentParser:
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
    return parser


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
    if args.json is not None and args.json.is_dir():
        parser.error(f"--json {args.json} is a directory; give the path of a file to write")
    if args.json is not None and args.json.exists() and not args.overwrite:
        parser.error(f"--json {args.json} exists: choose another file, or pass --overwrite")


# The sweep's names for the same things (the old spellings still work, with a note).
DEPRECATED_FLAGS = {
    "--steps": "--classifier-steps",
    "--eps": "--bsc-eps",
    "--traj-size": "--num-demos",
    "--methods": "--classifiers",
}


def load(args: argparse.Namespace) -> Demonstrations:
    """The demonstrations of ``--demos``, which must carry confidences; raises
    ``DemonstrationError`` or ``FileNotFoundError`` naming the file."""
    sizes = {}
    if args.env is not None:
        from pngail_jax import envs

        try:
            env = envs.make(args.env)
        except ValueError as error:
            raise DemonstrationError(f"--env: {error}") from None
        sizes = {"observation_size": env.observation_size, "action_size": env.action_size}
    demos = load_demonstrations(args.demos, args.conf, args.action_scale, **sizes)
    if demos.confidence is None:
        raise DemonstrationError(f"{args.demos}: these demonstrations carry no confidence")
    return demos


def check_labelled_mask(demos: Demonstrations, path: Path, num_labelled: int) -> None:
    """Raises ``DemonstrationError`` when the file's ``labelled`` mask allows fewer rows than
    the ``num_labelled`` asked for (the split labels only rows the mask allows)."""
    if demos.labelled is not None and demos.labelled.sum() < num_labelled:
        raise DemonstrationError(
            f"{path}: its labelled mask allows only {int(demos.labelled.sum())} of "
            f"{demos.num_rows} rows to be labelled, fewer than the {num_labelled} asked for "
            "(lower --label-ratio or --num-demos)"
        )


def main(argv=None) -> dict:
    """Trains the classifiers of the flags (every seed of each in one program), prints their
    errors (Table 1) and BSC risk variances (Table 5), and returns the summary."""
    args = parse_args(argv)
    demos = load_checked(args)
    traj_size, num_labelled = split_sizes(args, demos)
    config = classifier_config(args, traj_size, num_labelled)
    specs = [METHODS[m]() if m == "sc" else METHODS[m](args.bsc_eps) for m in args.classifiers]
    mask_note = (
        ""
        if demos.labelled is None
        else f" (at most, from the {int(demos.labelled.sum())} rows the file's mask allows)"
    )
    print(
        f"{demos.num_rows} rows from {args.demos}; {traj_size} per seed, {num_labelled} "
        f"labelled{mask_note}; {len(specs)} classifier(s) x {args.seeds} seeds x "
        f"{args.classifier_steps} steps of {config.labelled_batch_size} + "
        f"{config.unlabelled_batch_size} rows",
        flush=True,
    )
    start = time.perf_counter()
    results = train_all(args, demos, config, specs, traj_size)
    seconds = time.perf_counter() - start
    summary = error_table(args, results)
    variance_table(args, results, summary)
    print(
        f"\n{len(specs) * args.seeds} classifier runs in {seconds:.1f} s (one program, "
        "compilation included)"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, json_safe(summary))
        print(f"wrote {args.json}")
    return summary


def load_checked(args):
    """The demonstrations of ``--demos``, with the note on an applied action scale; a bad
    file ends in one line."""
    try:
        demos = load(args)
    except (DemonstrationError, FileNotFoundError) as error:
        raise SystemExit(f"classify: {error}") from None
    if action_scale_note(demos):
        print(action_scale_note(demos))
    return demos


def split_sizes(args, demos) -> tuple[int, int]:
    """Rows per seed's split and how many of them are labelled, checked against the file."""
    traj_size = demos.num_rows if args.num_demos is None else args.num_demos
    if not 2 <= traj_size <= demos.num_rows:
        raise SystemExit(f"--num-demos must be in [2, {demos.num_rows}], got {traj_size}")
    num_labelled = round(args.label_ratio * traj_size)
    if not 1 <= num_labelled < traj_size:
        raise SystemExit(
            f"label ratio {args.label_ratio} of {traj_size} rows leaves "
            f"{num_labelled} labelled: need at least one of each kind"
        )
    try:
        check_labelled_mask(demos, args.demos, num_labelled)
    except DemonstrationError as error:
        raise SystemExit(f"classify: {error}") from None
    return traj_size, num_labelled


def classifier_config(args, traj_size: int, num_labelled: int) -> ClassifierConfig:
    """The authors' batch: per labelled row, int(n_u / n_c) unlabelled rows."""
    authors = ClassifierConfig(num_steps=args.classifier_steps, labelled_batch_size=args.batch_size)
    return dataclasses.replace(
        authors, unlabelled_batch_size=authors.unlabelled_rows_per_step(traj_size, num_labelled)
    )


def train_all(args, demos, config: ClassifierConfig, specs, traj_size: int) -> dict:
    """Every classifier x seed as one ``jit(vmap)``; results with a leading [specs * seeds]
    axis, classifier-major."""
    stacked = jax.tree.map(lambda *x: jnp.repeat(jnp.stack(x), args.seeds, axis=0), *specs)
    keys = jnp.tile(jax.random.split(jax.random.key(args.seed), args.seeds), len(specs))

    def run(spec, key):
        return split_and_train(
            config,
            spec,
            jnp.asarray(demos.inputs),
            jnp.asarray(demos.confidence),
            traj_size,
            args.label_ratio,
            args.noise,
            key,
            allowed=None if demos.labelled is None else jnp.asarray(demos.labelled),
        )

    return jax.device_get(jax.jit(jax.vmap(run))(stacked, keys))


def error_table(args, results) -> dict:
    """Prints each classifier's MAE and RMSE on D_u over seeds; returns them by classifier."""
    summary = {}
    print("\n| method | MAE | RMSE | BSC clip active |\n|---|---|---|---|")
    for index, method in enumerate(args.classifiers):
        rows = slice(index * args.seeds, (index + 1) * args.seeds)
        mae, rmse = results["mae"][rows], results["rmse"][rows]
        summary[method] = {
            "mae_mean": float(mae.mean()),
            "mae_std": float(mae.std()),
            "rmse_mean": float(rmse.mean()),
            "rmse_std": float(rmse.std()),
        }
        clip = f"{results['clip_active'][rows].mean():.0%}" if method == "bsc" else "-"
        print(
            f"| {method.upper()} | {mae.mean():.3f} ± {mae.std():.3f} | "
            f"{rmse.mean():.3f} ± {rmse.std():.3f} | {clip} |"
        )
    return summary


def variance_table(args, results, summary: dict) -> None:
    """Prints Table 5 (the BSC risk's variance with and without alpha, beta) and adds it to
    ``summary``."""
    print(
        "\nTable 5, variance of the empirical BSC risk of each trained classifier "
        "(bootstrap over D_c and D_u; mean +- std over seeds):\n"
        "| method | alpha = beta = 0 (origin) | alpha = beta = n_u / (n_c + n_u) |\n"
        "|---|---|---|"
    )
    for index, method in enumerate(args.classifiers):
        rows = slice(index * args.seeds, (index + 1) * args.seeds)
        origin, balanced = results["variance_origin"][rows], results["variance_balanced"][rows]
        summary[method]["variance_origin"] = float(origin.mean())
        summary[method]["variance_balanced"] = float(balanced.mean())
        print(
            f"| {method.upper()} | {origin.mean():.2e} ± {origin.std():.1e} | "
            f"{balanced.mean():.2e} ± {balanced.std():.1e} |"
        )
