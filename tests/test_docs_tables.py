"""The docs' results tables that rest on committed run records are what their records give:
each ``<!-- record-table NAME -->`` table of README.md and docs/*.md equals
``run_records.record_table`` of ``records/NAME`` (checked first: digest, whole, both
statistics recomputed from its metrics). ``python -m experiments.record --docs`` rewrites
them."""

from pathlib import Path

import pytest

from pngail_jax import run_records
from pngail_jax.programs import record as program

ROOT = Path(__file__).resolve().parent.parent


def test_every_marked_table_equals_what_its_record_gives():
    checked = 0
    for path in program.doc_files(ROOT):
        for name, table, expected in program.marked_tables(path, ROOT / "records"):
            assert table == expected, (
                f"{path.relative_to(ROOT)}: the table of record {name} differs from its record; "
                "run python -m experiments.record --docs"
            )
            checked += 1
    assert checked >= 4  # the 10-seed Pendulum grid and the offline runs at least


def test_a_table_edited_by_hand_is_found_and_rewritten(tmp_path):
    """A number changed in a marked table fails the comparison, and --docs puts it back."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("no tables here\n")
    record = run_records.check_record(ROOT / "records" / "offline-pendulum")
    table = run_records.record_table(record, "bc-all")
    edited = table.replace("0.48 ± 0.04", "0.58 ± 0.04", 1)
    assert edited != table
    doc = tmp_path / "docs" / "results.md"
    doc.write_text(
        f"before\n\n<!-- record-table offline-pendulum baseline=bc-all -->\n{edited}"
        "<!-- /record-table -->\n\nafter\n"
    )
    [(name, found, expected)] = program.marked_tables(doc, ROOT / "records")
    assert name == "offline-pendulum" and found == edited and expected == table
    assert program.rewrite_docs(tmp_path, ROOT / "records") == [doc]
    assert doc.read_text().startswith("before\n\n<!-- record-table offline-pendulum")
    assert table in doc.read_text() and doc.read_text().endswith("\n\nafter\n")
    assert program.rewrite_docs(tmp_path, ROOT / "records") == []  # now current
    with pytest.raises(run_records.RecordError, match="has no method 'gail'"):
        run_records.record_table(record, "gail")
