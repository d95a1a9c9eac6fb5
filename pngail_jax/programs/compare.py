"""Compare methods across runs (or their committed records) and tasks: IQM, mean, median,
optimality gap, performance profiles and probabilities of improvement, with stratified
bootstrap intervals.

    python -m experiments.compare runs/pendulum runs/hopper runs/halfcheetah
    python -m experiments.compare runs/a runs/b --baseline gail --out runs/compare-ab
    python -m experiments.compare records/offline-hopper:bc-all,iswbc
                                  records/offline-hopper-dwbc5000:dwbc records/offline-ant

Reads each run's normalised returns (``metrics.csv`` of a sweep or an offline run, or a
committed run record's per-seed lists, the record checked first; runs of one task pool their
seeds); ``PATH:A,B`` takes only methods A and B of that run or record: a seed's score is
its mean over the last 20% of training (the headline, which two re-runs agree on best), or
with ``--statistic final`` its last evaluation. Writes to ``--out``: ``compare.json``,
``compare.md`` (the tables: the aggregates, then each task on its own) and
``aggregates.png``, ``profiles.png``, ``improvement.png``. The definitions:
``pngail_jax.analysis.compare`` (rliable's, Agarwal et al. 2021).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from pngail_jax.analysis import compare, report, run_records
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    claim_output,
    path_argument,
    text_argument,
)
from pngail_jax.storage.integrity import atomic_write_text
from pngail_jax.storage.outputs import claimed


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "compare", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument(
        "runs", nargs="+", type=source_argument, metavar="RUN_DIR",
        help="sweep or offline run directories, or run records (records/NAME), mixed freely "
        "(one or more per task; the same method's seeds of one task pool); RUN_DIR:A,B takes "
        "methods A and B of it alone (records/offline-hopper-dwbc5000:dwbc)",
    )  # fmt: skip
    parser.add_argument(
        "--baseline",
        help="the method every other is compared with, P(method > baseline) (default: pngail "
        "if the runs have it, else their first method)",
    )
    parser.add_argument("--out", type=path_argument, help="default runs/compare-<timestamp>")
    parser.add_argument(
        "--overwrite", action="store_true", help="replace a comparison already in --out"
    )
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's seed")
    parser.add_argument(
        "--statistic", choices=sorted(compare.STATISTICS), default=report.HEADLINE,
        help="a seed's score: late_average, its mean normalised return over the last "
        f"{report.LATE_SHARE * 100:.0f}%% of training (the default, the figure re-runs agree on "
        "best), or final, its last evaluation",
    )  # fmt: skip
    parser.add_argument(
        "--methods",
        help="comma-separated: compare these methods alone, in this order (default: every "
        "method of the runs; the aggregates use the tasks every compared method ran)",
    )
    add_allow_unsealed(parser.add_argument, "compare a run")
    parser.add_argument(
        "--expected", type=path_argument, metavar="RECORD",
        help="a kept run record (records/<name>, experiments.record): per method, is your "
        "runs' IQM inside the record's 95%% interval over seeds, and how far outside",
    )  # fmt: skip
    args = parser.parse_args(argv)
    for run in args.runs:
        if not run.path.is_dir():
            parser.error(f"{run.path} is not a directory")
    if args.out is None:
        args.out = Path("runs") / f"compare-{time.strftime('%Y%m%d-%H%M%S')}"
    if any(args.out.resolve() == run.path.resolve() for run in args.runs):
        parser.error(f"--out {args.out} is one of the runs: give another directory")
    claim_output(parser, args.out, "compare", args.overwrite)
    return args


def source_argument(text: str) -> compare.Source:
    """An argparse ``type``: a run's or a record's folder, ``PATH:A,B`` picking methods of it
    (``compare.parse_source``); an empty string is refused."""
    return compare.parse_source(text_argument(text))


def main(argv=None) -> Path:
    args = parse_args(argv)
    try:
        with refusals(), claimed(args.out, "compare", overwrite=args.overwrite) as claim:
            write_comparison(args, claim)
    except (compare.CompareError, RunError, run_records.RecordError) as error:
        raise SystemExit(str(error)) from None
    return args.out


def write_comparison(args, claim) -> None:
    """The comparison of ``args.runs`` into the claimed ``args.out``."""
    scores = compare.load_scores(args.runs, args.statistic, allow_unsealed=args.allow_unsealed)
    if args.methods is not None:
        scores = scores.only([name.strip() for name in args.methods.split(",") if name.strip()])
    baseline = args.baseline or ("pngail" if "pngail" in scores.methods else scores.methods[0])
    result = compare.compare(scores, baseline, seed=args.seed)
    expected, expected_text = _against_record(args, scores)
    claim.prepare()
    compare.write_result_json(
        args.out / "compare.json",
        {**result, "runs": [str(r) for r in args.runs], **expected},
    )
    text = compare.markdown(result) + expected_text
    atomic_write_text(args.out / "compare.md", text)
    compare.plot(result, args.out)
    print(text)
    print(f"wrote {args.out}/{{compare.json,compare.md,aggregates.png,profiles.png,"
          "improvement.png}")  # fmt: skip


def _against_record(args, scores) -> tuple[dict, str]:
    """``--expected``: ({"expected": rows, "expected_record": ...}, its markdown), or
    nothing without the flag. The record is verified first."""
    if args.expected is None:
        return {}, ""
    from pngail_jax.config.run_config import RunConfig  # JAX's import only with --expected
    from pngail_jax.jobs.offline_config import offline_defaults
    from pngail_jax.storage.integrity import read_json

    records = [str(run.path) for run in args.runs if compare.is_record(run.path)]
    if records:
        raise compare.CompareError(
            f"--expected sets runs against a record: {records[0]} is a record itself "
            "(compare it without --expected)"
        )
    record = run_records.check_record(args.expected)
    notes = run_records.check_comparable([run.path for run in args.runs], record)
    rows = run_records.expected_rows(scores, record)
    config = read_json(args.runs[0].path / "config.json", "run config")
    differences = run_records.config_differences(
        config, record, RunConfig().to_dict(), offline_defaults()
    )
    text = "\n" + run_records.expected_markdown(rows, record, differences, scores.statistic, notes)
    info = {"record": str(args.expected), "config_differences": differences, "rows": rows,
            "unfinished": notes}  # fmt: skip
    return {"expected": info}, text
