"""Kept records changed in place by this library's own operations, each checked whole after
and undone when the check fails: ``upgrade_record`` brings a record of the format before
``run_records.FORMAT`` up to date, ``thin_record`` keeps only the evaluated rows of a record
of every row (``run_records.ROWS``)."""

from __future__ import annotations

import gzip
from pathlib import Path

from pngail_jax.analysis.report import iterations_per_cell
from pngail_jax.analysis.run_records import (
    FORMAT,
    METRICS_FILE,
    RECORD_FILE,
    RecordError,
    check_record,
    kept_lines,
    metrics_entry,
    planned_iterations,
    sealed_record,
    write_metrics,
)
from pngail_jax.analysis.runs import read_run_config
from pngail_jax.storage.integrity import (
    IntegrityError,
    atomic_path,
    read_json,
    write_json,
)


def upgrade_record(folder: Path) -> dict:
    """Brings a record of the format before this one (2) to ``FORMAT``: an offline record's
    iterations done and planned (which format 2 left empty) from its config and metrics,
    ``unsealed`` None (format 2 did not keep whether the run's seal was checked), and its
    digest; then checks it whole, and puts the old file back when the check fails. Returns
    the checked record."""

    folder = Path(folder)
    path = folder / RECORD_FILE
    try:
        original = path.read_bytes()
        record = read_json(path, "run record")
    except FileNotFoundError:
        raise RecordError(f"{folder} holds no run record ({RECORD_FILE} is missing)") from None
    except (OSError, IntegrityError) as error:
        raise RecordError(f"{path}: unreadable ({error})") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT - 1:
        raise RecordError(f"{path}: not a run record of format {FORMAT - 1}, nothing to upgrade")
    command = record.get("command")
    if isinstance(command, list) and command[:3] == ["python", "-m", "offline"]:
        record["command"] = ["python", "-m", "experiments.offline", *command[3:]]  # format 2's slip
    offline = read_run_config(record.get("config") or {}).program == "offline"
    if offline and record.get("iterations") is None:
        try:
            reached = max(iterations_per_cell(folder / METRICS_FILE).values())
        except (ValueError, KeyError, TypeError, EOFError, OSError) as error:
            raise RecordError(f"{folder / METRICS_FILE} is damaged ({error})") from None
        record["iterations_done"] = reached
        record["iterations"] = planned_iterations(record["config"])
    record = sealed_record({**record, "format": FORMAT, "unsealed": record.get("unsealed")})
    write_json(path, record)
    try:
        return check_record(folder)
    except RecordError:
        with atomic_path(path) as temporary:
            temporary.write_bytes(original)
        raise


def thin_record(folder: Path) -> dict:
    """Keeps only the evaluated rows (and each cell's last) of the checked record of every
    row in ``folder``: its metrics file rewritten to those rows byte for byte, ``rows``
    "evaluated", ``thinned_from`` the size and SHA-256 of the file it had (so that file,
    kept elsewhere, can still be matched to it), its digest renewed; then checked whole
    (every statistic recomputed from the thinned file), and both files put back when the
    check fails. Returns the checked record."""

    folder = Path(folder)
    record = check_record(folder)
    if record.get("rows", "all") != "all":
        raise RecordError(f"{folder}: it keeps the {record['rows']} rows already")
    path, metrics = folder / RECORD_FILE, folder / METRICS_FILE
    originals = {path: path.read_bytes(), metrics: metrics.read_bytes()}
    kept = kept_lines(metrics, "evaluated")
    try:
        with gzip.open(metrics, "rb") as source:  # read whole before the new file replaces it
            write_metrics(metrics, source, kept)
        record = {**record, "rows": "evaluated", "thinned_from": record["metrics"],
                  "metrics": metrics_entry(metrics)}  # fmt: skip
        write_json(path, sealed_record(record))
        return check_record(folder)
    except BaseException:
        for original, content in originals.items():
            with atomic_path(original) as temporary:
                temporary.write_bytes(content)
        raise
