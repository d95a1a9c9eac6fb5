"""Which headline statistic a re-run would not overturn: a sweep run's seeds split in halves.

    python -m experiments.agreement runs/pendulum-10seeds --json agreement.json

Two re-runs of a grid differ the way two disjoint sets of its seeds do (a re-run on another
machine is, for a chaotic training run, another draw of the seed's trajectory: docs/sweep.md,
"What is reproducible"). So each statistic of a run's final performance (the last evaluation,
the mean of the last K evaluations, the mean over all of training) is scored by how well two
random halves of the seeds agree on it (``stats.split_half_agreement``): the methods' order
(Kendall's tau), the best method, and how far a method's figure moves. Reads metrics.csv (or a
record's metrics.csv.gz) only.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from pngail_jax.analysis.report import LATE_LABEL, late_average, late_evaluations, read_evaluations
from pngail_jax.analysis.stats import split_half_agreement
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    check_json_output,
    check_read_run,
    path_argument,
)
from pngail_jax.storage.integrity import write_json


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "agreement", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("run", type=path_argument, help="a sweep run (or record) directory")
    parser.add_argument("--lasts", default="1,3,5,10", help="K of 'the mean of the last K'")
    parser.add_argument("--splits", type=int, default=2000, help="random halvings")
    parser.add_argument("--json", type=path_argument, help="also write the rows here")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_allow_unsealed(parser.add_argument, "read a run")
    args = parser.parse_args(argv)
    check_json_output(parser, args.json, args.overwrite)
    found = [args.run / name for name in ("metrics.csv", "metrics.csv.gz")]
    args.metrics = next((path for path in found if path.is_file()), None)
    if args.metrics is None:
        parser.error(f"{args.run}: no metrics.csv there (not a sweep run or record)")
    check_read_run(parser, args.run, args.allow_unsealed)
    try:
        args.lasts = sorted({int(k) for k in args.lasts.split(",")})
    except ValueError:
        parser.error(f"--lasts takes positive integers, got {args.lasts!r}")
    if min(args.lasts) < 1 or args.splits < 1:
        parser.error("--lasts and --splits must be positive")
    return args


def statistics_of(evaluations: np.ndarray, lasts) -> dict[str, np.ndarray]:
    """Per seed float[S], from its evaluations float[S, E]: the mean of the last K for each
    K in ``lasts`` (K = 1: the final evaluation), the headline (the last ``LATE_SHARE`` of
    training, the summary's), all."""
    late = late_evaluations(evaluations.shape[1])  # = report.late_average's
    values = {
        ("final evaluation" if k == 1 else f"mean of the last {k}"): evaluations[:, -k:].mean(1)
        for k in lasts
        if k <= evaluations.shape[1]
    }
    values[f"{LATE_LABEL}, the headline ({late} evaluations)"] = late_average(evaluations)
    values["all of training"] = evaluations.mean(1)
    return values


def agreement_rows(metrics_path, lasts, num_splits: int) -> tuple[list[str], list[dict]]:
    evaluations = read_evaluations(
        metrics_path, "normalized_return", evaluated_by="eval_return", group_by=("method",)
    )
    methods = list(evaluations)
    too_few = [m[0] for m in methods if evaluations[m][1].shape[0] < 4]
    if too_few:
        raise SystemExit(f"{metrics_path}: {', '.join(too_few)} ran fewer than 4 seeds")
    per_method = [statistics_of(evaluations[m][1], lasts) for m in methods]
    rows = []
    for name in per_method[0]:
        scores = np.array([values[name] for values in per_method])
        if not np.isfinite(scores).all():
            raise SystemExit(f"{metrics_path}: a seed has no normalised return (diverged?)")
        rows.append({"statistic": name, **split_half_agreement(scores, num_splits=num_splits)})
    return [m[0] for m in methods], rows


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    methods, rows = agreement_rows(args.metrics, args.lasts, args.splits)
    seeds = 2 * rows[0]["half"]
    print(
        f"{args.run}: {len(methods)} methods, {seeds} seeds split at random into halves of "
        f"{rows[0]['half']}, {args.splits} times\n"
    )
    print("| statistic | Kendall tau between halves | same best method | mean abs. difference |")
    print("|---|---:|---:|---:|")
    for row in rows:
        difference = row["mean_abs_difference"]
        print(
            f"| {row['statistic']} | {row['kendall_tau']:.2f} | {row['same_best']:.0%} | "
            f"{'n/a' if math.isnan(difference) else f'{difference:.3f}'} |"
        )
    if args.json is not None:
        write_json(args.json, rows)
    return rows
