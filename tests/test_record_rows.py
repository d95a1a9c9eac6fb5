"""A record of the evaluated rows (``experiments.record --rows evaluated``, ``--thin``): its
metrics file is the run's lines of the evaluated iterations and each cell's last, byte for
byte; its statistics are those of the record of every row; ``--check`` refuses a row it
should not hold; thinning a kept record gives the bytes writing it thin gives, and is undone
when its check fails; the diagnostics table says what it averages."""

import csv
import gzip
import io
import json

import numpy as np
import pytest
from conftest import tiny_sweep_args

from pngail_jax.analysis import record_tables, record_upkeep, run_records
from pngail_jax.programs import record as program
from pngail_jax.programs import sweep


@pytest.fixture(scope="module")
def every_second(demos_path, tmp_path_factory):
    """A tiny finished run evaluated at iterations 2 and 4 of 4 (1 and 3 unevaluated)."""
    out = tmp_path_factory.mktemp("runs") / "run"
    arguments = tiny_sweep_args(demos_path, out)
    arguments[arguments.index("--eval-every") + 1] = "2"
    sweep.main(arguments)
    return out


def _lines(path) -> list[bytes]:
    opened = gzip.open(path, "rb") if path.suffix == ".gz" else path.open("rb")
    with opened as file:
        return file.read().splitlines(keepends=True)


def _fields(line: bytes, header: bytes) -> dict:
    """The columns of one metrics line under ``header``'s names."""
    names = next(csv.reader(io.StringIO(header.decode())))
    return dict(zip(names, next(csv.reader(io.StringIO(line.decode()))), strict=True))


def _record(run, tmp_path, name, *flags):
    [folder] = program.main([str(run), "--name", name, "--records", str(tmp_path), *flags])
    return folder, json.loads((folder / run_records.RECORD_FILE).read_text())


def test_a_record_of_the_evaluated_rows_keeps_those_lines_and_the_same_statistics(
    every_second, tmp_path, capsys
):
    thin, record = _record(every_second, tmp_path, "thin", "--rows", "evaluated")
    whole, full = _record(every_second, tmp_path, "whole")
    assert record["rows"] == "evaluated" and full["rows"] == "all"
    lines = _lines(every_second / "metrics.csv")
    expected = [lines[0]] + [
        line for line in lines[1:] if _fields(line, lines[0])["iteration"] in ("2", "4")
    ]
    assert len(expected) == 1 + 2 * 2 * 2  # methods x seeds x evaluated iterations
    assert _lines(thin / run_records.METRICS_FILE) == expected
    assert _lines(whole / run_records.METRICS_FILE) == lines
    for key in ("final_normalized_return", "late_average_normalized_return"):
        assert record[key] == full[key]
    assert record["iterations_done"] == full["iterations_done"] == 4
    assert record["training_seconds"] == full["training_seconds"]
    capsys.readouterr()
    program.main(["--check", str(thin)])
    assert "its evaluated rows" in capsys.readouterr().out
    # The diagnostics table: the mean over the evaluated rows, and its header says so.
    table = record_tables.diagnostics_table(record, thin, 10_000, ["pngail"]).splitlines()
    assert table[0].startswith("| M steps (means over the evaluated iterations) |")
    kept = [_fields(line, lines[0]) for line in expected[1:]]
    rewards = [float(row["mean_reward"]) for row in kept if row["method"] == "pngail"]
    [reward_row] = [row for row in table if row.startswith("| PN-GAIL: mean reward |")]
    assert reward_row.endswith(f" | {np.mean(rewards):.3f} |")
    assert record_tables.diagnostics_table(full, whole, 10_000, ["pngail"]).startswith(
        "| M steps | "
    )


def test_check_refuses_a_thin_records_unevaluated_row(every_second, tmp_path):
    """A record that says "evaluated" but holds a row of an unevaluated iteration, its
    metrics digest and its own digest remade as a careful forger would."""
    from pngail_jax.storage.integrity import file_digest

    thin, record = _record(every_second, tmp_path, "thin", "--rows", "evaluated")
    metrics = thin / run_records.METRICS_FILE
    lines = _lines(every_second / "metrics.csv")
    extra = next(line for line in lines[1:] if _fields(line, lines[0])["iteration"] == "1")
    edited = b"".join([*_lines(metrics), extra])
    with gzip.GzipFile(metrics, "wb", mtime=0) as file:
        file.write(edited)
    record["metrics"] = {**record["metrics"], "bytes": metrics.stat().st_size,
                         "sha256": file_digest(metrics)}  # fmt: skip
    (thin / run_records.RECORD_FILE).write_text(json.dumps(run_records.sealed_record(record)))
    with pytest.raises(SystemExit, match="holds rows without an evaluation before each cell"):
        program.main(["--check", str(thin)])
    record["rows"] = "some"
    (thin / run_records.RECORD_FILE).write_text(json.dumps(run_records.sealed_record(record)))
    with pytest.raises(SystemExit, match="rows 'some' is not one of all, evaluated"):
        program.main(["--check", str(thin)])


def test_thinning_a_kept_record_gives_the_thin_records_bytes(every_second, tmp_path, monkeypatch):
    thin, record = _record(every_second, tmp_path, "thin", "--rows", "evaluated")
    kept, full = _record(every_second, tmp_path, "kept")
    program.main(["--thin", str(kept)])
    thinned = json.loads((kept / run_records.RECORD_FILE).read_text())
    assert (kept / run_records.METRICS_FILE).read_bytes() == (
        thin / run_records.METRICS_FILE
    ).read_bytes()
    assert thinned["thinned_from"] == full["metrics"]
    assert {k: v for k, v in thinned.items() if k not in ("thinned_from", "digest", "name")} == {
        k: v for k, v in record.items() if k not in ("digest", "name")
    }
    with pytest.raises(SystemExit, match="it keeps the evaluated rows already"):
        program.main(["--thin", str(kept)])
    # A check that fails after the rewrite puts both files back as they were.
    again, _ = _record(every_second, tmp_path, "again")
    before = {path.name: path.read_bytes() for path in again.iterdir()}
    calls = []

    def failing_second_check(folder):
        calls.append(folder)
        if len(calls) > 1:
            raise run_records.RecordError("the check failed")
        return run_records.check_record(folder)

    monkeypatch.setattr(record_upkeep, "check_record", failing_second_check)
    with pytest.raises(SystemExit, match="the check failed"):
        program.main(["--thin", str(again)])
    assert {path.name: path.read_bytes() for path in again.iterdir()} == before


def test_a_cut_runs_last_rows_are_kept_though_unevaluated(tmp_path):
    """Each cell's last row stays (it says how far the run got), evaluated or not."""
    metrics = tmp_path / "metrics.csv"
    rows = [("a", 0, 1, ""), ("a", 0, 2, "-100"), ("a", 0, 3, ""), ("b", 0, 1, ""),
            ("b", 0, 2, "")]  # fmt: skip
    lines = ["method,seed,setting,iteration,eval_return"]
    lines += [f'{m},{s},"x=1,y=2",{i},{r}' for m, s, i, r in rows]
    metrics.write_text("\r\n".join(lines) + "\r\n")
    assert run_records.kept_lines(metrics, "evaluated") == {0, 2, 3, 5}
    assert run_records.kept_lines(metrics, "all") is None
    with pytest.raises(run_records.RecordError, match="rows 'most': give one of all, evaluated"):
        run_records.kept_lines(metrics, "most")


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--check", "records/x", "--rows", "evaluated"], "--rows is for writing a record"),
        (["--thin", "records/x", "--name", "y"], "--thin takes the records to thin alone"),
        (["--thin"], "--thin takes the records to thin alone"),
    ],
)
def test_the_rows_flags_clash_in_one_line(arguments, message, capsys):
    with pytest.raises(SystemExit):
        program.parse_args(arguments)
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert message in error
