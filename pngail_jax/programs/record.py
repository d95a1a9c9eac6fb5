"""Keep a sweep run as a small record to commit, or check records already kept.

    python -m experiments.record runs/hopper-cpu --name hopper-cpu   # -> records/hopper-cpu/
    python -m experiments.record --check records/hopper-cpu records/pendulum-1000
    python -m experiments.record --docs          # rewrite the docs' tables from their records

A record (``pngail_jax.run_records``) holds the run's config, command, commit, machine,
training seconds, each method's final normalised returns per seed, and its metrics.csv
gzipped (every cell and iteration): what a results table in the docs rests on, without
checkpoints, policies or plots. Writing one checks it; ``--check`` verifies kept ones (the
metrics file against its digest, whole against the config, the final returns recomputed).
A table in README.md or docs/ between ``<!-- record-table NAME -->`` and
``<!-- /record-table -->`` is ``run_records.record_table`` of ``records/NAME`` (with
``baseline=METHOD`` after the name: each method's probability of improvement over it), and one
between ``<!-- record-glance NAME NAME ... -->`` and ``<!-- /record-glance -->`` is
``run_records.glance_table`` of those records (a row per task), and one between
``<!-- record-comparison NAME -->`` and ``<!-- /record-comparison -->`` the table of a
recorded ``experiments.compare_settings`` comparison (``jobs.comparison_record``: RUN_DIR a
finished comparison's folder); ``<!-- record-contrast NAME NAME ... baseline=ARM
arms=A,B -->`` (closed by ``<!-- /record-contrast -->``) puts several comparisons' arms beside
each one's baseline on the task's own physics, with each arm's probability of improvement;
``<!-- record-blocks NAME block=STEPS -->`` and
``<!-- record-diagnostics NAME block=STEPS [methods=A,B] -->`` (closed by ``<!--
/record-blocks -->`` and ``<!-- /record-diagnostics -->``) give a record's learning and its
diagnostics per block of environment steps, and ``<!-- record-seeds NAME turn=LEVEL
[methods=A,B] -->`` (closed by ``<!-- /record-seeds -->``) its seeds side by side (the
lowest evaluation, the turn above LEVEL, the classifier's error): ``--docs`` writes them,
and tests/test_docs_tables.py fails when one differs from its records.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from pngail_jax import run_records
from pngail_jax.jobs import comparison_record
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    path_argument,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "record", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("paths", nargs="*", type=path_argument, metavar="RUN_DIR",
                        help="a sweep or offline run, or a finished compare_settings comparison, "
                        "to record; with --check, records to verify")  # fmt: skip
    parser.add_argument("--name", help="the record's folder name under --records")
    parser.add_argument(
        "--records", type=path_argument, default=Path("records"),
        help="where records are kept (default records/; experiments.paper's runs go to results/)",
    )  # fmt: skip
    parser.add_argument("--check", action="store_true", help="verify records instead")
    add_allow_unsealed(
        parser.add_argument, "record a sweep or offline run (a comparison has no seal)"
    )
    parser.add_argument(
        "--docs", action="store_true",
        help="rewrite every record-table, record-glance, record-comparison, record-contrast, "
        "record-blocks, record-diagnostics and record-seeds table of README.md and docs/*.md "
        "from its records (checked first)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.docs:
        if args.paths or args.name or args.check:
            parser.error("--docs takes no run, --name or --check")
        return args
    if not args.check and (len(args.paths) != 1 or not args.name):
        parser.error("record one run at a time: RUN_DIR --name NAME (or --check RECORD ...)")
    if args.check and not args.paths:
        parser.error("--check needs the records to verify: --check records/NAME ...")
    if args.check and args.name:
        parser.error("--check verifies records; --name is for writing one")
    return args


MARKED = re.compile(
    r"(<!-- record-table (?P<name>[\w.-]+)(?: baseline=(?P<baseline>[\w.+-]+))? -->\n)"
    r"(?P<table>.*?)(?P<end><!-- /record-table -->)",
    re.S,
)
# A compare_settings comparison's table (``jobs.comparison_record``).
COMPARED = re.compile(
    r"(<!-- record-comparison (?P<name>[\w.-]+) -->\n)(?P<table>.*?)"
    r"(?P<end><!-- /record-comparison -->)",
    re.S,
)
# A recorded run's learning or diagnostics per block of environment steps
# (``run_records.block_table``, ``run_records.diagnostics_table``).
BLOCKED = re.compile(
    r"(<!-- record-(?P<kind>blocks|diagnostics) (?P<name>[\w.-]+) block=(?P<block>\d+)"
    r"(?: methods=(?P<methods>[\w.+,-]+))? -->\n)(?P<table>.*?)(?P<end><!-- /record-(?P=kind) -->)",
    re.S,
)
# A recorded run's seeds side by side (``run_records.seed_table``).
SEEDED = re.compile(
    r"(<!-- record-seeds (?P<name>[\w.-]+) turn=(?P<turn>-?[\d.]+)"
    r"(?: methods=(?P<methods>[\w.+,-]+))? -->\n)(?P<table>.*?)(?P<end><!-- /record-seeds -->)",
    re.S,
)
# Several comparisons' arms against each one's baseline (``comparison_record.contrast_table``).
CONTRASTED = re.compile(
    r"(<!-- record-contrast (?P<name>[\w.-]+(?: [\w.-]+)*) baseline=(?P<baseline>[\w.-]+) "
    r"arms=(?P<arms>[\w.,-]+) -->\n)(?P<table>.*?)(?P<end><!-- /record-contrast -->)",
    re.S,
)
# Several records in one table (``run_records.glance_table``): names separated by spaces.
GLANCED = re.compile(
    r"(<!-- record-glance (?P<name>[\w.-]+(?: [\w.-]+)*) -->\n)"
    r"(?P<table>.*?)(?P<end><!-- /record-glance -->)",
    re.S,
)


PATTERNS = (MARKED, GLANCED, COMPARED, BLOCKED, CONTRASTED, SEEDED)


def doc_files(root: Path = Path(".")) -> list[Path]:
    """The documents whose tables may rest on records: README.md and docs/*.md."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def _methods(match: re.Match) -> list[str] | None:
    """A marker's ``methods=A,B`` as a list (None where it names none: every method)."""
    return match["methods"].split(",") if match["methods"] else None


def _expected(match: re.Match, records: Path) -> str:
    """The table a marker's records give (RecordError for one missing or failing its check)."""
    if match.re is COMPARED:
        return comparison_record.table(comparison_record.check(records / match["name"])) + "\n"
    if match.re is BLOCKED:
        folder = records / match["name"]
        record, block = run_records.check_record(folder), int(match["block"])
        if match["kind"] == "blocks":
            return run_records.block_table(record, folder, block)
        return run_records.diagnostics_table(record, folder, block, _methods(match))
    if match.re is SEEDED:
        folder = records / match["name"]
        return run_records.seed_table(
            run_records.check_record(folder), folder, float(match["turn"]), _methods(match)
        )
    if match.re is CONTRASTED:
        checked = [comparison_record.check(records / name) for name in match["name"].split()]
        return comparison_record.contrast_table(
            checked, match["arms"].split(","), match["baseline"]
        )
    if match.re is GLANCED:
        names = match["name"].split()
        return run_records.glance_table([run_records.check_record(records / n) for n in names])
    record = run_records.check_record(records / match["name"])
    return run_records.record_table(record, match["baseline"])


def marked_tables(path: Path, records: Path = Path("records")) -> list[tuple[str, str, str]]:
    """(record name or names, the table in ``path``, the table its records give) for each
    marked table of ``path``; RecordError for a record missing or failing its check."""
    text = path.read_text()
    return [
        (match["name"], match["table"], _expected(match, records))
        for pattern in PATTERNS
        for match in pattern.finditer(text)
    ]


def rewrite_docs(root: Path = Path("."), records: Path = Path("records")) -> list[Path]:
    """Every marked table of ``doc_files`` rewritten from its records; returns the files
    changed."""
    changed = []
    for path in doc_files(root):
        text = path.read_text()
        new = text
        for pattern in PATTERNS:
            new = pattern.sub(lambda m: m[1] + _expected(m, records) + m["end"], new)
        if new != text:
            path.write_text(new)
            changed.append(path)
    return changed


def main(argv=None) -> list[Path]:
    args = parse_args(argv)
    try:
        if args.docs:
            changed = rewrite_docs(records=args.records)
            print(
                "rewrote " + (", ".join(map(str, changed)) if changed else "nothing (all current)")
            )
            return changed
        if args.check:
            for folder in args.paths:
                print(f"ok  {describe_checked(folder)}")
            return list(args.paths)
        if comparison_record.is_comparison(args.paths[0]):
            folder = comparison_record.write(args.paths[0], args.name, args.records)
        else:
            folder = run_records.write_record(
                args.paths[0], args.name, args.records, allow_unsealed=args.allow_unsealed
            )
        print(f"wrote {folder} and checked it\n    {describe_checked(folder)}")
    except run_records.RecordError as error:
        raise SystemExit(str(error)) from None
    return [folder]


def describe_checked(folder: Path) -> str:
    """The record in ``folder`` checked (a sweep's or a comparison's) and described."""
    if (Path(folder) / run_records.METRICS_FILE).exists():
        return run_records.describe(run_records.check_record(folder))
    return comparison_record.describe(comparison_record.check(folder))
