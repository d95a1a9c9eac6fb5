"""Keep a sweep run as a small record to commit, or check records already kept.

    python -m experiments.record runs/hopper-cpu --name hopper-cpu   # -> records/hopper-cpu/
    python -m experiments.record --check records/hopper-cpu records/pendulum-1000
    python -m experiments.record --docs          # rewrite the docs' tables from their records
    python -m experiments.record --reproduce check-pendulum   # re-run a record here, check it

A record (``pngail_jax.analysis.run_records``) holds the run's config, command, commit, machine,
training seconds, each method's final normalised returns per seed, and its metrics.csv
gzipped (every cell and iteration; with ``--rows evaluated`` the evaluated iterations and each
cell's last alone, for a run whose every row would be megabytes; ``--thin records/NAME`` does
that to a kept record): what a results table in the docs rests on, without checkpoints,
policies or plots. Writing one checks it; ``--check`` verifies kept ones (the
metrics file against its digest, whole against the config, the final returns recomputed).
A table in README.md or a page under docs/ between ``<!-- record-table NAME -->`` and
``<!-- /record-table -->`` is ``record_tables.record_table`` of ``records/NAME`` (with
``baseline=METHOD`` after the name: each method's probability of improvement over it), and one
between ``<!-- record-glance NAME NAME ... -->`` and ``<!-- /record-glance -->`` is
``record_tables.glance_table`` of those records (a row per task; ``NAME:A,B`` takes only
methods A and B of that record), and one between
``<!-- record-comparison NAME -->`` and ``<!-- /record-comparison -->`` the table of a
recorded ``experiments.compare_settings`` comparison (``jobs.comparison_record``: RUN_DIR a
finished comparison's folder); ``<!-- record-contrast NAME NAME ... baseline=ARM
arms=A,B -->`` (closed by ``<!-- /record-contrast -->``) puts several comparisons' arms beside
each one's baseline on the task's own physics, with each arm's probability of improvement;
``<!-- record-blocks NAME block=STEPS -->`` and
``<!-- record-diagnostics NAME block=STEPS [methods=A,B] -->`` (closed by ``<!--
/record-blocks -->`` and ``<!-- /record-diagnostics -->``) give a record's learning and its
diagnostics per block of environment steps (record-blocks of an offline record: per block
of gradient steps), and ``<!-- record-seeds NAME turn=LEVEL
[methods=A,B] -->`` (closed by ``<!-- /record-seeds -->``) its seeds side by side (the
lowest evaluation, the turn above LEVEL, the classifier's error): ``--docs`` writes them,
and tests/test_docs_tables.py fails when one differs from its records. Both read every
marker of a document with ``parse_markers``, which refuses in one line naming the file and
line a marker it cannot read (one not closed before the next, a closing one with none open,
an unknown kind or option, a value that does not parse); ``--docs`` reads every document's
markers and computes every table before it writes any, so a broken one writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from collections.abc import Callable
from pathlib import Path

from pngail_jax.analysis import record_tables, record_upkeep, run_records
from pngail_jax.jobs import comparison_record
from pngail_jax.programs.cli import (
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    path_argument,
)
from pngail_jax.storage.integrity import atomic_write_text


def build_parser() -> ArgumentParser:
    """The record program's flags."""
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
    parser.add_argument(
        "--upgrade", action="store_true",
        help="bring run records of the format before this one up to date (their digest added, "
        "checked whole; the file is left as it was when the check fails)",
    )  # fmt: skip
    parser.add_argument(
        "--rows", choices=run_records.ROWS, default="all",
        help="the run's metrics rows the record keeps: all (default), or evaluated (the "
        "evaluated iterations and each cell's last: a tenth or less of a long run's file; the "
        "diagnostics tables then average those rows)",
    )  # fmt: skip
    parser.add_argument(
        "--thin", action="store_true",
        help="keep only the evaluated rows of kept records of every row (as --rows evaluated "
        "would have; checked whole after, left as they were when the check fails)",
    )  # fmt: skip
    add_allow_unsealed(
        parser.add_argument, "record a sweep or offline run (a comparison has no seal)"
    )
    parser.add_argument(
        "--docs", action="store_true",
        help="rewrite every record-table, record-glance, record-comparison, record-contrast, "
        "record-blocks, record-diagnostics and record-seeds table of README.md and docs/**/*.md "
        "from its records (checked first)",
    )  # fmt: skip
    parser.add_argument(
        "--reproduce", metavar="NAME",
        help="run the record NAME's command into --out and check the result against the "
        "record: every seed to the last bit with the record's code and machine, else compare "
        "--expected's interval (exit 1 when a method disagrees); a cut re-run continues when "
        "run again (programs/reproduce.py)",
    )  # fmt: skip
    parser.add_argument(
        "--out", type=path_argument,
        help="with --reproduce: the re-run's folder (default runs/reproduce-NAME)",
    )  # fmt: skip
    return parser


def parse_args(argv=None) -> argparse.Namespace:
    """The flags of ``argv``, one of the program's modes (record, --check, --upgrade, --thin,
    --docs, --reproduce) with only the flags it takes; else one line naming the clash."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.rows != "all" and (args.check or args.upgrade or args.thin or args.docs
                               or args.reproduce is not None):  # fmt: skip
        parser.error("--rows is for writing a record from a run (a kept one: --thin)")
    if args.thin:
        if not args.paths or args.name or args.check or args.upgrade or args.docs:
            parser.error("--thin takes the records to thin alone: --thin records/NAME ...")
        if args.reproduce is not None or args.out is not None or args.allow_unsealed:
            parser.error("--thin takes the records to thin alone: --thin records/NAME ...")
        return args
    if args.reproduce is not None:
        if args.paths or args.name or args.check or args.upgrade or args.docs:
            parser.error("--reproduce NAME takes --out and --records alone")
        if args.allow_unsealed:
            parser.error("--allow-unsealed is for writing a record from a run, not --reproduce")
        return args
    if args.out is not None:
        parser.error("--out is for --reproduce NAME")
    if args.docs:
        if args.paths or args.name or args.check or args.upgrade:
            parser.error("--docs takes no run, --name, --check or --upgrade")
        return args
    if args.upgrade:
        if not args.paths or args.name or args.check:
            parser.error("--upgrade takes the records to upgrade alone: --upgrade records/NAME ...")
        return args
    if not args.check and (len(args.paths) != 1 or not args.name):
        parser.error("record one run at a time: RUN_DIR --name NAME (or --check RECORD ...)")
    if args.check and not args.paths:
        parser.error("--check needs the records to verify: --check records/NAME ...")
    if args.check and args.name:
        parser.error("--check verifies records; --name is for writing one")
    return args


RECORD_NAME = re.compile(r"[\w.-]+")  # a folder of records/
METHOD_NAME = re.compile(r"[\w.+-]+")  # a method of a record (bc-all, pngail)
ARM_NAME = re.compile(r"[\w.-]+")  # an arm of a compare_settings comparison


# Option parsers: each gives the value as the table wants it, or ValueError saying what the
# value must be.


def _word(value: str, pattern: re.Pattern, what: str) -> str:
    if not pattern.fullmatch(value):
        raise ValueError(f"must be {what}")
    return value


def _method(value: str) -> str:
    return _word(value, METHOD_NAME, "a method's name")


def _methods(value: str) -> list[str]:
    return [_word(name, METHOD_NAME, "methods' names, A,B") for name in value.split(",")]


def _arm(value: str) -> str:
    return _word(value, ARM_NAME, "an arm's name")


def _arms(value: str) -> list[str]:
    return [_word(name, ARM_NAME, "arms' names, A,B") for name in value.split(",")]


def _block_steps(value: str) -> int:
    if not re.fullmatch(r"[0-9]+", value) or int(value) == 0:
        raise ValueError("must be a positive whole number of steps")
    return int(value)


def _level(value: str) -> float:
    try:
        level = float(value)
    except ValueError:
        level = math.nan
    if not math.isfinite(level):
        raise ValueError("must be a number")
    return level


@dataclasses.dataclass(frozen=True)
class MarkerKind:
    """What one kind of record marker takes: one record name or several, and its options,
    each with its parser (the value as the table wants it, or ValueError saying what the value
    must be)."""

    usage: str  # the marker as the docs write it
    several_records: bool = False
    picks: bool = False  # a name may be NAME:A,B, only those methods of that record
    required: dict[str, Callable[[str], object]] = dataclasses.field(default_factory=dict)
    optional: dict[str, Callable[[str], object]] = dataclasses.field(default_factory=dict)


# Every kind a marker may have, keyed by what follows ``record-``. record-blocks takes no
# methods= (``record_tables.block_table`` shows every method), so one given there is refused
# rather than ignored.
MARKER_KINDS = {
    "table": MarkerKind("record-table NAME [baseline=METHOD]", optional={"baseline": _method}),
    "glance": MarkerKind("record-glance NAME[:A,B] NAME ...", several_records=True, picks=True),
    "comparison": MarkerKind("record-comparison NAME"),
    "blocks": MarkerKind("record-blocks NAME block=STEPS", required={"block": _block_steps}),
    "diagnostics": MarkerKind(
        "record-diagnostics NAME block=STEPS [methods=A,B]",
        required={"block": _block_steps},
        optional={"methods": _methods},
    ),
    "seeds": MarkerKind(
        "record-seeds NAME turn=LEVEL [methods=A,B]",
        required={"turn": _level},
        optional={"methods": _methods},
    ),
    "contrast": MarkerKind(
        "record-contrast NAME NAME ... baseline=ARM arms=A,B",
        several_records=True,
        required={"baseline": _arm, "arms": _arms},
    ),
}

# A record marker: a whole line ``<!-- record-KIND ... -->`` or ``<!-- /record-KIND -->``.
MARKER_LINE = re.compile(r"<!--\s*(?P<closing>/?)record-(?P<body>.*?)\s*-->(?P<rest>.*)")
# Anything that looks like one, wherever it is on a line.
MARKER_START = re.compile(r"<!--\s*/?record-")
FENCE = re.compile(r"\s*(?P<fence>`{3,}|~{3,})")


@dataclasses.dataclass(frozen=True)
class Marker:
    """One marked table of a document: its kind, record names and options (parsed), the
    opening marker's line number, and the table between the markers with its character
    offsets in the document's text."""

    kind: str
    names: tuple[str, ...]
    options: dict[str, object]
    line: int
    start: int
    end: int
    table: str


def _marker_line(where: str, line: str) -> tuple[bool, str, list[str]] | None:
    """(closing, kind, the words after the kind) of a marker line; None for a line holding
    none. A marker not alone on its line, unindented, is refused: the table it would open
    would be left unchecked (a mention in prose is quoted in backticks)."""
    line = line.rstrip("\n")
    for found in MARKER_START.finditer(line):
        if found.start() > 0 and line[found.start() - 1] != "`":
            raise run_records.RecordError(
                f"{where}: a record marker must stand alone on its line, unindented "
                "(to mention one in prose, quote it in backticks)"
            )
    if not MARKER_START.match(line):
        return None
    marker = MARKER_LINE.fullmatch(line)
    if marker is None:
        raise run_records.RecordError(f"{where}: a record marker must end with --> on its line")
    if marker["rest"].strip():
        raise run_records.RecordError(f"{where}: nothing may follow a record marker on its line")
    kind, *words = marker["body"].split() or [""]
    if kind not in MARKER_KINDS:
        known = ", ".join(f"record-{name}" for name in MARKER_KINDS)
        raise run_records.RecordError(
            f"{where}: unknown record marker kind 'record-{kind}' (known: {known})"
        )
    return bool(marker["closing"]), kind, words


def _opening(where: str, kind: str, words: list[str]) -> tuple[tuple[str, ...], dict]:
    """The record names and parsed options of an opening marker's words; RecordError for a
    wrong number of names, a name or option it does not take, a value that does not parse or
    a required option missing."""
    spec = MARKER_KINDS[kind]
    usage = f"(<!-- {spec.usage} -->)"
    names = tuple(word for word in words if "=" not in word)
    if not names or (len(names) > 1 and not spec.several_records):
        wanted = "one record name or more" if spec.several_records else "one record name"
        raise run_records.RecordError(
            f"{where}: record-{kind} takes {wanted}, not {len(names)} {usage}"
        )
    names, picks = _picked_names(where, kind, names)
    parsers, options = spec.required | spec.optional, ({"picks": picks} if picks else {})
    for word in words:
        if "=" not in word:
            continue
        key, value = word.split("=", 1)
        if key not in parsers:
            raise run_records.RecordError(
                f"{where}: record-{kind} takes no option '{key}=' {usage}"
            )
        if key in options:
            raise run_records.RecordError(f"{where}: record-{kind} has {key}= twice")
        try:
            options[key] = parsers[key](value)
        except ValueError as error:
            raise run_records.RecordError(
                f"{where}: record-{kind} {word}: {key}= {error}"
            ) from None
    missing = [f"{key}=" for key in spec.required if key not in options]
    if missing:
        raise run_records.RecordError(
            f"{where}: record-{kind} needs {' and '.join(missing)} {usage}"
        )
    return names, options


def _picked_names(where: str, kind: str, words) -> tuple[tuple[str, ...], dict]:
    """The record names of an opening marker's name words, and the methods picked from each
    written ``NAME:A,B`` (only in a kind that takes picks); RecordError for a word that is not
    a record's name, or picks that do not parse or that the kind does not take."""
    usage = f"(<!-- {MARKER_KINDS[kind].usage} -->)"
    names, picks = [], {}
    for word in words:
        name, colon, methods = word.partition(":")
        if not RECORD_NAME.fullmatch(name):
            raise run_records.RecordError(f"{where}: '{word}' is not a record's name {usage}")
        if colon and not MARKER_KINDS[kind].picks:
            raise run_records.RecordError(
                f"{where}: record-{kind} takes whole records, not {word} {usage}"
            )
        if colon:
            try:
                picks[name] = _methods(methods)
            except ValueError as error:
                raise run_records.RecordError(f"{where}: record-{kind} {word}: {error}") from None
        names.append(name)
    return tuple(names), picks


def parse_markers(path: Path, text: str) -> list[Marker]:
    """Every marked table of ``text`` (the document at ``path``), read before anything is
    written; RecordError naming ``path:line`` for a marker not closed by one of its kind
    before the next marker (or the end), a closing marker with nothing open, an unknown kind
    or option, a value that does not parse, a required option missing, or a marker not alone
    on its line. Lines in fenced code blocks are text, not markers."""
    markers, opened, offset = [], None, 0
    fence, fence_line, hidden = "", 0, 0  # an open code fence, where, a marker line inside
    for number, line in enumerate(re.split(r"(?<=\n)", text), start=1):
        where, start, offset = f"{path}:{number}", offset, offset + len(line)
        if fence:
            closing = line.strip()
            if closing and set(closing) == {fence[0]} and len(closing) >= len(fence):
                fence = ""
            elif not hidden and MARKER_START.search(line):
                hidden = number
            continue
        if found := FENCE.match(line):
            fence, fence_line, hidden = found["fence"], number, 0
            continue
        marker = _marker_line(where, line)
        if marker is None:
            continue
        closing, kind, words = marker
        if closing:
            if words:
                raise run_records.RecordError(
                    f"{where}: a closing marker is <!-- /record-{kind} -->, with nothing more"
                )
            if opened is None:
                raise run_records.RecordError(
                    f"{where}: <!-- /record-{kind} --> closes no marker (none is open)"
                )
            if opened["kind"] != kind:
                raise run_records.RecordError(
                    f"{where}: <!-- /record-{kind} --> cannot close the record-{opened['kind']} "
                    f"marker of line {opened['line']}"
                )
            table = text[opened["start"] : start]
            markers.append(Marker(**opened, end=start, table=table))
            opened = None
            continue
        if opened is not None:
            raise run_records.RecordError(
                f"{path}:{opened['line']}: the record-{opened['kind']} marker is not closed "
                f"by <!-- /record-{opened['kind']} --> before the next marker, on line {number}"
            )
        names, options = _opening(where, kind, words)
        opened = dict(kind=kind, names=names, options=options, line=number, start=offset)
    if opened is not None:
        raise run_records.RecordError(
            f"{path}:{opened['line']}: the record-{opened['kind']} marker is never closed by "
            f"<!-- /record-{opened['kind']} -->"
        )
    if fence and hidden:
        raise run_records.RecordError(
            f"{path}:{fence_line}: this code fence is never closed, and hides the record "
            f"marker of line {hidden}"
        )
    return markers


def doc_files(root: Path = Path(".")) -> list[Path]:
    """The documents whose tables may rest on records: README.md and every page under docs/
    (docs/results/*.md included: the results pages are split by subject, and a new page is
    found without a list to keep)."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def _expected(marker: Marker, records: Path) -> str:
    """The table a marker's records give (RecordError for one missing or failing its check)."""
    folders = [records / name for name in marker.names]
    options = marker.options
    if marker.kind == "comparison":
        return comparison_record.table(comparison_record.check(folders[0])) + "\n"
    if marker.kind == "contrast":
        checked = [comparison_record.check(folder) for folder in folders]
        return comparison_record.contrast_table(checked, options["arms"], options["baseline"])
    checked = [run_records.check_record(folder) for folder in folders]
    if marker.kind == "glance":
        return record_tables.glance_table(checked, picks=options.get("picks"))
    if marker.kind == "table":
        return record_tables.record_table(checked[0], options.get("baseline"))
    if marker.kind == "blocks":
        return record_tables.block_table(checked[0], folders[0], options["block"])
    if marker.kind == "diagnostics":
        return record_tables.diagnostics_table(
            checked[0], folders[0], options["block"], options.get("methods")
        )
    return record_tables.seed_table(checked[0], folders[0], options["turn"], options.get("methods"))


def _expected_tables(path: Path, markers: list[Marker], records: Path) -> list[str]:
    """Each marker's expected table; a record's RecordError is prefixed with the marker's
    ``path:line``, so the failing marker is found."""
    tables = []
    for marker in markers:
        try:
            tables.append(_expected(marker, records))
        except run_records.RecordError as error:
            raise run_records.RecordError(f"{path}:{marker.line}: {error}") from None
    return tables


def marked_tables(path: Path, records: Path = Path("records")) -> list[tuple[str, str, str]]:
    """(record name or names, the table in ``path``, the table its records give) for each
    marked table of ``path``, in the file's order; RecordError for a broken marker
    (``parse_markers``) or a record missing or failing its check."""
    markers = parse_markers(path, path.read_text())
    expected = _expected_tables(path, markers, records)
    return [
        (" ".join(marker.names), marker.table, table)
        for marker, table in zip(markers, expected, strict=True)
    ]


def _with_tables(text: str, markers: list[Marker], tables: list[str]) -> str:
    """``text`` with each marker's table replaced by the matching one of ``tables``."""
    pieces, cursor = [], 0
    for marker, table in zip(markers, tables, strict=True):
        pieces += [text[cursor : marker.start], table]
        cursor = marker.end
    return "".join(pieces) + text[cursor:]


def rewrite_docs(root: Path = Path("."), records: Path = Path("records")) -> list[Path]:
    """Every marked table of ``doc_files`` rewritten from its records; returns the files
    changed. Every file's markers are parsed first, then every table computed (its records
    checked), and only then is anything written, so a broken marker or record anywhere raises
    RecordError and leaves every file as it was; each changed file is written atomically."""
    texts = {path: path.read_text() for path in doc_files(root)}
    markers = {path: parse_markers(path, text) for path, text in texts.items()}
    rewritten = {}
    for path, text in texts.items():
        tables = _expected_tables(path, markers[path], records)
        new = _with_tables(text, markers[path], tables)
        if new != text:
            rewritten[path] = new
    for path, new in rewritten.items():
        atomic_write_text(path, new)
    return list(rewritten)


def main(argv=None) -> list[Path]:
    args = parse_args(argv)
    try:
        if args.reproduce is not None:
            from pngail_jax.programs import reproduce  # its checks import JAX: only here

            out = args.out or reproduce.default_out(args.reproduce)
            if not reproduce.reproduce(args.reproduce, args.records, out):
                raise SystemExit(1)
            return [out]
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
        if args.upgrade:
            for folder in args.paths:
                record = record_upkeep.upgrade_record(folder)
                print(f"upgraded {folder} to format {record['format']}, and checked it")
            return list(args.paths)
        if args.thin:
            for folder in args.paths:
                record = record_upkeep.thin_record(folder)
                print(f"thinned {folder} to its evaluated rows, and checked it\n    "
                      f"{run_records.describe(record)}")  # fmt: skip
            return list(args.paths)
        if comparison_record.is_comparison(args.paths[0]):
            if args.rows != "all":
                raise run_records.RecordError("--rows is for a sweep or offline run's record")
            folder = comparison_record.write(args.paths[0], args.name, args.records)
        else:
            folder = run_records.write_record(
                args.paths[0], args.name, args.records, allow_unsealed=args.allow_unsealed,
                rows=args.rows,
            )  # fmt: skip
        print(f"wrote {folder} and checked it\n    {describe_checked(folder)}")
    except run_records.RecordError as error:
        raise SystemExit(str(error)) from None
    return [folder]


def describe_checked(folder: Path) -> str:
    """The record in ``folder`` checked (a sweep's or a comparison's) and described."""
    if (Path(folder) / run_records.METRICS_FILE).exists():
        return run_records.describe(run_records.check_record(folder))
    return comparison_record.describe(comparison_record.check(folder))
