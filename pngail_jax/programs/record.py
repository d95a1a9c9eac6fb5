"""Keep a sweep run as a small record to commit, or check records already kept.

    python -m experiments.record runs/hopper-cpu --name hopper-cpu   # -> records/hopper-cpu/
    python -m experiments.record --check records/hopper-cpu records/pendulum-1000

A record (``pngail_jax.run_records``) holds the run's config, command, commit, machine,
training seconds, each method's final normalised returns per seed, and its metrics.csv
gzipped (every cell and iteration): what a results table in the docs rests on, without
checkpoints, policies or plots. Writing one checks it; ``--check`` verifies kept ones (the
metrics file against its digest, whole against the config, the final returns recomputed).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pngail_jax import run_records
from pngail_jax.programs.cli import ArgumentParser, HelpFormatter, path_argument


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "record", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("paths", nargs="+", type=path_argument, metavar="RUN_DIR",
                        help="a sweep run to record; with --check, records to verify")  # fmt: skip
    parser.add_argument("--name", help="the record's folder name under --records")
    parser.add_argument(
        "--records", type=path_argument, default=Path("records"),
        help="where records are kept (default records/; experiments.paper's runs go to results/)",
    )  # fmt: skip
    parser.add_argument("--check", action="store_true", help="verify records instead")
    args = parser.parse_args(argv)
    if not args.check and (len(args.paths) != 1 or not args.name):
        parser.error("record one run at a time: RUN_DIR --name NAME (or --check RECORD ...)")
    if args.check and args.name:
        parser.error("--check verifies records; --name is for writing one")
    return args


def main(argv=None) -> list[Path]:
    args = parse_args(argv)
    try:
        if args.check:
            for folder in args.paths:
                print(f"ok  {run_records.describe(run_records.check_record(folder))}")
            return list(args.paths)
        folder = run_records.write_record(args.paths[0], args.name, args.records)
    except run_records.RecordError as error:
        raise SystemExit(str(error)) from None
    print(f"wrote {folder}/{{record.json,metrics.csv.gz}} and checked it")
    print(f"    {run_records.describe(run_records.check_record(folder))}")
    return [folder]
