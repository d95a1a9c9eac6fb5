"""Why one seed did better than another: a sweep run's seeds side by side.

    python -m experiments.seeds runs/A --method pngail
    python -m experiments.seeds runs/A --method pngail --share 0.2 --json seeds.json

For each seed of a method (and setting): its final and averaged normalised returns, its
confidence classifier's error on D_u, and how its training went over the last ``--share`` of
the iterations and over all of them: the discriminator's accuracy on agent and demonstration
rows (near 1 on both: a saturated discriminator, whose reward no longer guides the policy),
the mean reward it paid the policy, and the TRPO step's KL. Seeds are sorted by final return,
so a split between good and bad seeds reads from the top down. Reads ``metrics.csv`` and
``summary.json`` only: it runs on a finished or a partial run, on any machine.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pngail_jax.analysis.report import LATE_LABEL, LATE_SHARE, metrics_rows
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    check_json_output,
    check_read_run,
    path_argument,
)
from pngail_jax.storage.integrity import IntegrityError, read_json, write_json

TRAINING_COLUMNS = ("disc_acc_agent", "disc_acc_demo", "mean_reward", "kl")


def parse_args(argv=None):
    parser = ArgumentParser(
        "seeds", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("run", type=path_argument, help="a sweep run directory")
    parser.add_argument("--method", default="pngail", help="the method whose seeds to compare")
    parser.add_argument(
        "--setting",
        help="the setting label, e.g. 'label_ratio=0.2,noise=0' (default: the only one)",
    )
    parser.add_argument(
        "--share",
        type=float,
        default=LATE_SHARE,
        help="the last share of the iterations that 'late' columns average over",
    )
    parser.add_argument("--json", type=path_argument, help="also write the table here")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_allow_unsealed(parser.add_argument, "read a run")
    args = parser.parse_args(argv)
    check_json_output(parser, args.json, args.overwrite)
    if not (math.isfinite(args.share) and 0 < args.share <= 1):
        parser.error(f"--share must lie in (0, 1], got {args.share}")
    for name in ("metrics.csv", "summary.json"):
        if not (args.run / name).is_file():
            parser.error(f"{args.run}: no {name} there (not a sweep run, or not started)")
    check_read_run(parser, args.run, args.allow_unsealed)
    return args


def read_training(path: Path, method: str, setting: str | None) -> tuple[str, dict]:
    """(setting, {seed: {column: float[iterations]}}) of one method from metrics.csv."""
    rows: dict[str, dict[int, dict[str, list[float]]]] = {}
    for row in metrics_rows(path):
        if row["method"] != method:
            continue
        columns = rows.setdefault(row["setting"], {}).setdefault(int(row["seed"]), {})
        for name in TRAINING_COLUMNS:
            value = row.get(name, "")
            columns.setdefault(name, []).append(float(value) if value else math.nan)
    if not rows:
        raise SystemExit(f"{path}: no rows of method {method!r}")
    if setting is None:
        if len(rows) > 1:
            raise SystemExit(f"{path}: several settings, pick one with --setting: {sorted(rows)}")
        setting = next(iter(rows))
    if setting not in rows:
        raise SystemExit(f"{path}: no setting {setting!r} for {method}; there are {sorted(rows)}")
    return setting, {
        seed: {name: np.asarray(values) for name, values in columns.items()}
        for seed, columns in rows[setting].items()
    }


def seed_table(run: Path, method: str, setting: str | None = None, share: float = LATE_SHARE):
    """One dict per seed, sorted by its normalised return over the last ``LATE_SHARE`` of
    training (best first)."""
    setting, training = read_training(run / "metrics.csv", method, setting)
    try:
        summary = read_json(run / "summary.json", "run summary")
    except IntegrityError as error:
        raise SystemExit(str(error)) from None
    # summary.json's key: the method, plus its setting when the grid has more than one
    label = next(
        (key for key in (f"{method} [{setting}]", method) if key in summary["methods"]), None
    )
    if label is None:
        raise SystemExit(f"{run}/summary.json has no method {method!r} at {setting!r}")
    per_seed = {row["seed"]: row for row in summary["methods"][label]["per_seed"]}
    table = []
    for seed, columns in sorted(training.items()):
        late = max(1, math.ceil(share * len(columns["kl"])))
        row = {"seed": seed}
        for name in ("final_normalized_return", "late_average_normalized_return"):
            value = per_seed.get(seed, {}).get(name)
            if value is None:  # no return range: the raw return, named so
                value = per_seed.get(seed, {}).get(name.replace("_normalized", ""))
            row[name] = math.nan if value is None else value
        for name in ("confidence_mae", "confidence_rmse"):
            value = per_seed.get(seed, {}).get(name)
            row[name] = math.nan if value is None else value
        for name, values in columns.items():
            row[f"{name}_late"] = float(np.nanmean(values[-late:]))
            row[f"{name}_all"] = float(np.nanmean(values))
        table.append(row)
    table.sort(key=lambda r: -np.nan_to_num(r["late_average_normalized_return"], nan=-np.inf))
    return setting, table


def markdown(method: str, setting: str, table: list[dict], share: float) -> str:
    def number(value, digits=2):
        return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"

    lines = [
        f"{method} ({setting}), seeds by their normalised return over the {LATE_LABEL} "
        f"(the headline figure); 'late' diagnostics: the last {share:.0%} of the iterations",
        "",
        f"| seed | {LATE_LABEL} | final | classifier MAE | RMSE | D acc. agent (late / all) | "
        "D acc. demo (late / all) | mean reward (late) | KL (late / all) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in table:
        lines.append(
            f"| {row['seed']} | {number(row['late_average_normalized_return'])} | "
            f"{number(row['final_normalized_return'])} | "
            f"{number(row['confidence_mae'], 3)} | {number(row['confidence_rmse'], 3)} | "
            f"{number(row['disc_acc_agent_late'])} / {number(row['disc_acc_agent_all'])} | "
            f"{number(row['disc_acc_demo_late'])} / {number(row['disc_acc_demo_all'])} | "
            f"{number(row['mean_reward_late'], 3)} | "
            f"{number(row['kl_late'], 4)} / {number(row['kl_all'], 4)} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    setting, table = seed_table(args.run, args.method, args.setting, args.share)
    print(markdown(args.method, setting, table, args.share))
    if args.json is not None:
        write_json(args.json, json.loads(json.dumps(table).replace("NaN", "null")))
    return table
