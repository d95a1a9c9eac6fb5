"""The docs' results tables that rest on committed run records are what their records give:
each ``<!-- record-table NAME -->`` table of README.md and docs/**/*.md equals
``record_tables.record_table`` of ``records/NAME`` (checked first: digest, whole, both
statistics recomputed from its metrics). ``python -m experiments.record --docs`` rewrites
them."""

import re
from pathlib import Path

import numpy as np
import pytest

from pngail_jax.analysis import record_tables, run_records
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
    table = record_tables.record_table(record, "bc-all")
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
        record_tables.record_table(record, "gail")


def test_the_results_pages_are_read_and_their_tables_rewritten(tmp_path):
    """The results are split by subject into docs/results/*.md: ``doc_files`` holds every
    one of them (the marked-table test above checks each), and ``--docs`` rewrites a stale
    table on a page below docs/ as on one in it."""
    pages = program.doc_files(ROOT)
    split = sorted((ROOT / "docs" / "results").glob("*.md"))
    assert len(split) >= 5 and set(split) <= set(pages)
    markers = sum(len(program.parse_markers(page, page.read_text())) for page in split)
    assert markers >= 20  # the 25 M, 2.5 M, Pendulum, remedy and offline records' tables
    (tmp_path / "docs" / "results").mkdir(parents=True)
    (tmp_path / "README.md").write_text("none\n")
    page = tmp_path / "docs" / "results" / "offline.md"
    page.write_text("<!-- record-table offline-hopper -->\n| old |\n<!-- /record-table -->\n")
    assert program.rewrite_docs(tmp_path, ROOT / "records") == [page]
    [(name, written, expected)] = program.marked_tables(page, ROOT / "records")
    assert name == "offline-hopper" and written == expected != "| old |\n"


def test_a_glance_table_joins_records_by_task():
    """A row per task, the records of one task joined (Pendulum's ILID comes from its own
    record), each cell the headline's mean ± s.e. over seeds, computed here in NumPy; a
    method in two records of one task is refused."""
    names = ["offline-pendulum", "offline-pendulum-ilid", "offline-hopper"]
    records = [run_records.check_record(ROOT / "records" / name) for name in names]
    lines = record_tables.glance_table(records).splitlines()
    assert lines[0] == (
        "| task (seeds) | BC (expert rows) | BC (all rows) | DWBC | ISW-BC | ILID |"
    )
    pendulum, hopper = lines[2].split(" | "), lines[3].split(" | ")
    assert pendulum[0] == "| Pendulum-v1 (5)" and hopper[0] == "| Hopper-v4 (5)"
    assert hopper[-1] == "- |"  # ILID needs trajectories, which Hopper's file does not keep
    seeds = np.asarray(records[0]["late_average_normalized_return"]["iswbc"], float)
    mean, se = seeds.mean(), seeds.std(ddof=1) / np.sqrt(len(seeds))
    assert pendulum[4] == f"{mean:.2f} ± {se:.2f}"
    with pytest.raises(
        run_records.RecordError, match="'bc-expert' on Pendulum-v1 is in another record"
    ):
        record_tables.glance_table([records[0], records[0]])


def test_a_glance_table_takes_a_method_from_the_record_a_marker_picks():
    """``NAME:A,B`` takes only those methods of a record: DWBC from its own record beside the
    other methods of the task's, in the paper's column order; a method a record does not have
    is refused in one line, and so is the marker's table."""
    names = ["offline-pendulum", "offline-pendulum-dwbc5000"]
    records = [run_records.check_record(ROOT / "records" / name) for name in names]
    with pytest.raises(run_records.RecordError, match="'dwbc' on Pendulum-v1 is in another"):
        record_tables.glance_table(records)
    picks = {"offline-pendulum": ["bc-expert", "bc-all", "iswbc"], names[1]: ["dwbc"]}
    lines = record_tables.glance_table(records, picks=picks).splitlines()
    assert lines[0] == "| task (seeds) | BC (expert rows) | BC (all rows) | DWBC | ISW-BC |"
    seeds = np.asarray(records[1]["late_average_normalized_return"]["dwbc"], float)
    mean, se = seeds.mean(), seeds.std(ddof=1) / np.sqrt(len(seeds))
    assert lines[2].split(" | ")[3] == f"{mean:.2f} ± {se:.2f}"
    with pytest.raises(run_records.RecordError, match="record offline-pendulum has no method 'x'"):
        record_tables.glance_table(records[:1], picks={"offline-pendulum": ["x"]})
    marker = f"<!-- record-glance offline-pendulum:bc-all {names[1]}:dwbc -->"
    (parsed,) = program.parse_markers(Path("page.md"), f"{marker}\n<!-- /record-glance -->\n")
    assert parsed.names == tuple(names)
    assert parsed.options == {"picks": {"offline-pendulum": ["bc-all"], names[1]: ["dwbc"]}}


# The results tables of these documents, outside the record markers, each say where their
# numbers rest: a record (``records/NAME``) or "record not kept", in the table or in the line
# right above it. A results table is one whose header names a result or whose cells hold a
# mean ± s.e. or an interval; throughput, fidelity and settings tables are not (their headers
# below).
SPLIT_RESULTS = sorted(f"docs/results/{page.name}" for page in (ROOT / "docs/results").glob("*.md"))
RESULT_DOCS = ("README.md", "docs/results.md", *SPLIT_RESULTS, "docs/ppo.md", "docs/performance.md",
               "docs/demonstrations.md")  # fmt: skip
RESULT_HEADERS = ("final", "iqm", "return", "mae", "accuracy", "p(", "per seed", "average")
NOT_RESULTS = ("steps/s", "envs x steps per iteration", "rows per step")
INTERVAL = re.compile(r"\d ± \d|\d \[-?\d")  # a mean ± s.e. or an estimate [its interval]


def _row(line: str) -> bool:
    return line.lstrip().startswith("|")  # a table in a list item is indented


def results_tables(text: str):
    """(line number, table text, the nearest non-blank line above) of each results table
    outside ``<!-- record-... -->`` blocks."""
    lines, inside = text.split("\n"), False
    for number, line in enumerate(lines):
        inside = (inside or line.startswith("<!-- record-")) and not line.startswith("<!-- /")
        if not _row(line) or (number and _row(lines[number - 1])):
            continue
        end = number
        while end < len(lines) and _row(lines[end]):
            end += 1
        header, body = line.lower(), "\n".join(lines[number + 2 : end])
        if inside or not (any(w in header for w in RESULT_HEADERS) or INTERVAL.search(body)):
            continue
        if any(word in header for word in NOT_RESULTS):
            continue
        above = next((lines[k] for k in range(number - 1, -1, -1) if lines[k].strip()), "")
        yield number + 1, "\n".join(lines[number:end]), above


def _says_where(table: str, above: str) -> bool:
    text = f"{above}\n{table}".lower()
    return "records/" in text or "record not kept" in text


@pytest.mark.parametrize("name", RESULT_DOCS)
def test_every_results_table_names_its_record_or_says_it_was_not_kept(name):
    text = (ROOT / name).read_text()
    silent = [number for number, table, above in results_tables(text)
              if not _says_where(table, above)]  # fmt: skip
    assert not silent, f"{name}: results tables on lines {silent} name no record"


def test_an_unmarked_results_table_is_found():
    table = "| method | final |\n|---|---:|\n| GAIL | 0.30 ± 0.00 |"
    found = list(results_tables(f"Some text.\n\n{table}\n"))
    assert [number for number, _, _ in found] == [3] and not _says_where(*found[0][1:])
    marked = list(results_tables(f"(record not kept)\n\n{table}\n"))
    assert _says_where(*marked[0][1:])
    fenced = f"<!-- record-table x -->\n{table}\n<!-- /record-table -->\n"
    assert list(results_tables(fenced)) == []
    assert list(results_tables("| task | training steps/s |\n|---|---:|\n| a | 1 |")) == []


def test_the_readme_states_the_records_total_size():
    """The README's "(`records/`, X MB in all)" is the folder's size to the 0.1 MB."""
    stated = re.search(r"`records/`, ([\d.]+) MB in all", (ROOT / "README.md").read_text())
    assert stated, "README.md states no total size of records/"
    total = sum(f.stat().st_size for f in (ROOT / "records").rglob("*") if f.is_file())
    assert float(stated[1]) == round(total / 1e6, 1), f"records/ holds {total / 1e6:.2f} MB"


def _metrics(name: str) -> list[dict]:
    import csv
    import gzip

    with gzip.open(ROOT / "records" / name / "metrics.csv.gz", "rt", newline="") as file:
        return list(csv.DictReader(file))


def test_the_block_table_is_each_seeds_block_mean_then_mean_and_se_over_seeds():
    """A block table's cells recomputed from the record's metrics file in plain NumPy: each
    seed's mean normalised evaluation over the evaluations in (0, 0.5 M], (0.5 M, 1 M], ...,
    then mean ± s.e. (ddof 1) over seeds; the last column the final evaluation."""
    folder = ROOT / "records" / "pendulum-500-5seeds"
    record = run_records.check_record(folder)
    table = record_tables.block_table(record, folder, 500_000).splitlines()
    assert table[0] == "| M steps | 0-0.5 | 0.5-1 | 1-1.5 | 1.5-2 | 2-2.5 | final (2.5 M) |"
    rows = [
        r for r in _metrics("pendulum-500-5seeds") if r["method"] == "pngail" and r["eval_return"]
    ]
    edges = [(low, low + 500_000) for low in range(0, 2_500_000, 500_000)]
    cells = _numpy_block_cells(rows, lambda r: int(r["env_steps"]), edges)
    assert "| PN-GAIL | " + " | ".join(cells) + " |" in table


def _numpy_block_cells(rows, step, edges) -> list[str]:
    """The block table's cells in plain NumPy: per (low, high] of ``edges``, each seed's mean
    normalised return over its evaluated ``rows`` whose ``step(row)`` falls there, then
    "mean ± s.e." (ddof 1) over seeds; the final evaluation's last."""

    def mean_se(values) -> str:
        return f"{np.mean(values):.2f} ± {np.std(values, ddof=1) / np.sqrt(len(values)):.2f}"

    seeds = sorted({r["seed"] for r in rows})
    cells = [
        mean_se([np.mean([float(r["normalized_return"]) for r in rows
                          if r["seed"] == seed and low < step(r) <= high]) for seed in seeds])
        for low, high in edges
    ]  # fmt: skip
    last = max(step(r) for r in rows)
    return cells + [mean_se([float(r["normalized_return"]) for r in rows if step(r) == last])]


def test_an_offline_records_blocks_are_gradient_steps():
    """An offline record has no environment steps: its blocks are spans of gradient steps
    (iteration x the run's steps per iteration), labelled in thousands; each cell is each
    seed's block mean, then mean ± s.e. over seeds, recomputed here in plain NumPy."""
    folder = ROOT / "records" / "offline-pendulum"
    record = run_records.check_record(folder)
    table = record_tables.block_table(record, folder, 20_000).splitlines()
    assert table[0] == "| k gradient steps | 0-20 | 20-40 | 40-50 | final (50 k) |"
    per_iteration = record["config"]["config"]["steps_per_iteration"]
    rows = [r for r in _metrics("offline-pendulum") if r["method"] == "bc-all" and r["eval_return"]]
    edges = [(0, 20_000), (20_000, 40_000), (40_000, 50_000)]
    cells = _numpy_block_cells(rows, lambda r: int(r["iteration"]) * per_iteration, edges)
    assert "| BC (all rows) | " + " | ".join(cells) + " |" in table


def test_the_diagnostics_table_is_the_block_mean_over_iterations_and_seeds(tmp_path):
    folder = ROOT / "records" / "pendulum-500-5seeds"
    record = run_records.check_record(folder)
    table = record_tables.diagnostics_table(record, folder, 1_000_000, ["pngail"]).splitlines()
    assert table[0] == "| M steps | 0-1 | 1-2 | 2-2.5 |" and len(table) == 2 + 5
    rows = [r for r in _metrics("pendulum-500-5seeds") if r["method"] == "pngail"]
    late = [float(r["mean_reward"]) for r in rows if int(r["env_steps"]) > 2_000_000]
    assert table[4].startswith("| PN-GAIL: mean reward |")
    assert table[4].endswith(f" | {np.mean(late):.3f} |")
    # the markers: a stale table is rewritten from the record, and then equals it
    page = _stale_page(
        tmp_path,
        "<!-- record-blocks pendulum-500-5seeds block=500000 -->\n| old |\n"
        "<!-- /record-blocks -->\n"
        "<!-- record-diagnostics pendulum-500-5seeds block=1000000 methods=pngail -->\n| old |\n"
        "<!-- /record-diagnostics -->\n",
    )
    assert program.rewrite_docs(tmp_path, ROOT / "records") == [page]
    found = program.marked_tables(page, ROOT / "records")
    assert len(found) == 2 and all(written == expected for _, written, expected in found)
    assert "\n".join(table) + "\n" in page.read_text()


def _stale_page(root: Path, text: str) -> Path:
    """docs/results.md under ``root`` holding ``text`` (beside a README without markers)."""
    (root / "docs").mkdir()
    (root / "README.md").write_text("none\n")
    page = root / "docs" / "results.md"
    page.write_text(text)
    return page


def _synthetic_record(tmp_path, rows) -> Path:
    """A folder holding only a metrics.csv.gz of ``rows`` (method, seed, env_steps,
    normalised return or None for a diverged evaluation, mean reward)."""
    import gzip

    lines = ["method,seed,setting,iteration,env_steps,eval_return,normalized_return,mean_reward"]
    for method, seed, steps, value, reward in rows:
        ret = "" if value is None else f"{value}"
        lines.append(f"{method},{seed},s,{steps // 100},{steps},{ret},{ret},{reward}")
    tmp_path.mkdir(exist_ok=True)
    with gzip.open(tmp_path / run_records.METRICS_FILE, "wt") as file:
        file.write("\n".join(lines) + "\n")
    return tmp_path


def test_block_tables_leave_out_a_diverged_seed_and_refuse_what_has_no_blocks(tmp_path):
    """A seed without a final evaluation is out of every column (as from the headline); a
    block is a span of environment steps, so an offline run (0 steps) and a block of 0 are
    refused in one line, and so is a method the run does not have."""
    rows = [
        ("gail", seed, steps, value, 0.5)
        for seed, offset in ((0, 0.0), (1, 0.2))
        for steps, value in ((100, 0.1 + offset), (200, 0.3 + offset), (300, 0.5 + offset))
    ]
    pngail = {0: (0.0, 0.2, 0.4), 1: (0.9, None, None)}  # seed 1 diverges after 100 steps
    rows += [("pngail", seed, steps, value, 0.1 if steps < 300 else 0.3)
             for seed, values in pngail.items()
             for steps, value in zip((100, 200, 300), values, strict=True)]  # fmt: skip
    folder, record = _synthetic_record(tmp_path, rows), {"name": "synthetic"}
    table = record_tables.block_table(record, folder, 200).splitlines()
    assert table[0] == "| M steps | 0-0.0002 | 0.0002-0.0003 | final (0.0003 M) |"
    assert table[2] == "| GAIL | 0.30 ± 0.10 | 0.60 ± 0.10 | 0.60 ± 0.10 |"  # (0.1+0.3)/2, +0.2
    assert table[3] == "| PN-GAIL | 0.10 ± nan | 0.40 ± nan | 0.40 ± nan |"  # seed 1 left out
    diagnostics = record_tables.diagnostics_table(record, folder, 200, ["pngail"]).splitlines()
    assert diagnostics[2] == "| PN-GAIL: mean reward | 0.100 | 0.300 |"
    with pytest.raises(run_records.RecordError, match="no method 'wgail'"):
        record_tables.diagnostics_table(record, folder, 200, ["wgail"])
    with pytest.raises(run_records.RecordError, match="a block of 0 steps"):
        record_tables.block_table(record, folder, 0)
    offline = _synthetic_record(tmp_path / "offline", [("bc", 0, 0, 0.5, 0.0)])
    with pytest.raises(run_records.RecordError, match="no environment steps"):
        record_tables.diagnostics_table(record, offline, 200)


def test_the_seed_table_names_each_seeds_low_point_turn_and_classifier_error(tmp_path):
    """A seed's lowest evaluation and where, the first of three evaluations in a row above
    the level (a dip after two above does not count), the record's final and late figures
    and its classifier error; GAIL reads no confidences; a marker rewrites it."""
    pngail = {0: (0.2, -0.1, 0.4, 0.1, 0.5, 0.6, 0.7), 1: (0.5, 0.6, 0.7, 0.8, 0.2, 0.1, 0.0)}
    rows = [("pngail", seed, 100 * (i + 1), value, 0.1)
            for seed, values in pngail.items() for i, value in enumerate(values)]  # fmt: skip
    rows += [("gail", seed, 100 * (i + 1), 0.1, 0.4) for seed in (0, 1) for i in range(7)]
    folder = _synthetic_record(tmp_path / "synthetic", rows)
    record = {
        "name": "synthetic",
        "final_normalized_return": {"gail": [0.1, 0.1], "pngail": [0.7, None]},
        "late_average_normalized_return": {"gail": [0.1, 0.1], "pngail": [0.65, 0.05]},
        "confidence_mae": {"gail": [0.2, 0.3], "pngail": [0.25, None]},
    }
    table = record_tables.seed_table(record, folder, 0.3).splitlines()
    assert table[0] == (
        "| method | seed | final | last 20% of training | lowest evaluation (at M steps) | "
        "turned above 0.3 (M steps) | confidence MAE on D_u |"
    )
    assert table[2:] == [
        "| PN-GAIL | 0 | 0.70 | 0.65 | -0.10 (0.0002) | 0.0005 | 0.250 |",
        "| PN-GAIL | 1 | diverged | 0.05 | 0.00 (0.0007) | 0.0001 | not recorded |",
        "| GAIL | 0 | 0.10 | 0.10 | 0.10 (0.0001) | never | reads none |",
        "| GAIL | 1 | 0.10 | 0.10 | 0.10 (0.0001) | never | reads none |",
    ]
    assert record_tables.seed_table(record, folder, 0.3, ["gail"]).splitlines()[2:] == table[4:]
    with pytest.raises(run_records.RecordError, match="no method 'wgail'"):
        record_tables.seed_table(record, folder, 0.3, ["wgail"])
    # the marker, on a real record (made before classifier errors were kept)
    page = _stale_page(
        tmp_path,
        "<!-- record-seeds pendulum-500-5seeds turn=0.5 methods=pngail -->\n| old |\n"
        "<!-- /record-seeds -->\n",
    )
    assert program.rewrite_docs(tmp_path, ROOT / "records") == [page]
    [(_, written, expected)] = program.marked_tables(page, ROOT / "records")
    assert written == expected and len(expected.splitlines()) == 2 + 5
    assert expected.splitlines()[2].endswith(" | not recorded |")


def test_every_record_marker_in_the_docs_is_one_the_program_reads():
    """A marker with a typo would leave its table unchecked by both tests: every line of the
    docs that opens a record marker is a marked table of the program's parser (which refuses
    a marker it cannot read)."""
    for path in program.doc_files(ROOT):
        text = path.read_text()
        opened = [line for line in text.split("\n") if line.startswith("<!-- record-")]
        markers = program.parse_markers(path, text)
        assert len(opened) == len(markers), f"{path.name}: a record marker the parser skips"


# -- broken markers: refused in one line naming file:line, before anything is written ------

COMPARISON = "settings-hopper-v4-value-epochs"  # a committed comparison record
STALE_COMPARISON = (
    f"<!-- record-comparison {COMPARISON} -->\n| stale |\n<!-- /record-comparison -->\n"
)


def _run_docs(root: Path, monkeypatch) -> None:
    """``python -m experiments.record --docs`` run in ``root`` on the committed records."""
    monkeypatch.chdir(root)
    program.main(["--docs", "--records", str(ROOT / "records")])


def test_a_missing_closing_marker_writes_nothing_and_names_the_line(tmp_path, monkeypatch):
    """The red team's page: the first table's closing marker deleted. Matched from its
    opening to the next table's closing marker, --docs used to delete the prose, the code
    block and the next table between them; now it names the opening marker's line and
    leaves every file byte for byte, the README's stale table (which reads fine) included."""
    page = _stale_page(
        tmp_path,
        "# Results\n\n"
        "<!-- record-table pendulum-1000-5seeds -->\n| method | final |\n|---|---:|\n\n"
        "Prose that explains the table.\n\n```python\nprint('a code block')\n```\n\n"
        "<!-- record-table pendulum-500-5seeds -->\n| method | final |\n"
        "<!-- /record-table -->\n\nafter\n",
    )
    readme = tmp_path / "README.md"
    readme.write_text(STALE_COMPARISON)
    before = {path: path.read_bytes() for path in (page, readme)}
    with pytest.raises(SystemExit, match=re.escape(
        "docs/results.md:3: the record-table marker is not closed by <!-- /record-table --> "
        "before the next marker, on line 13"
    )):  # fmt: skip
        _run_docs(tmp_path, monkeypatch)
    assert {path: path.read_bytes() for path in (page, readme)} == before
    with pytest.raises(run_records.RecordError, match=r"results\.md:3: .* not closed"):
        program.marked_tables(page, ROOT / "records")  # so the docs test fails on it too
    page.write_text("<!-- record-table pendulum-1000-5seeds -->\n| method | final |\n")
    with pytest.raises(run_records.RecordError, match=r"results\.md:1: .* never closed by"):
        program.rewrite_docs(tmp_path, ROOT / "records")


@pytest.mark.parametrize(
    ("marker", "message"),
    [
        ("<!-- record-tabel pendulum-10seeds -->", "unknown record marker kind 'record-tabel'"),
        ("<!-- record-blocks swimmer-25M block=500k -->",
         "record-blocks block=500k: block= must be a positive whole number"),
        ("<!-- record-blocks swimmer-25M block=0 -->",
         "record-blocks block=0: block= must be a positive whole number"),
        ("<!-- record-table pendulum-10seeds basline=gail -->",
         "record-table takes no option 'basline='"),
        ("<!-- record-blocks swimmer-25M block=500000 methods=gail -->",
         "record-blocks takes no option 'methods='"),  # block_table shows every method
        ("<!-- record-seeds swimmer-25M turn=high -->",
         "record-seeds turn=high: turn= must be a number"),
        ("<!-- record-diagnostics swimmer-25M block=500000 methods=gail,,pngail -->",
         "record-diagnostics methods=gail,,pngail: methods= must be methods' names, A,B"),
        ("<!-- record-diagnostics swimmer-25M -->", "record-diagnostics needs block="),
        ("<!-- record-contrast a b baseline=reference -->", "record-contrast needs arms="),
        ("<!-- record-table pendulum-10seeds pendulum-1000-5seeds -->",
         "record-table takes one record name, not 2"),
        ("<!-- record-glance -->", "record-glance takes one record name or more, not 0"),
        ("<!-- record-table pendulum-10seeds:gail -->",
         "record-table takes whole records, not pendulum-10seeds:gail"),
        ("<!-- record-glance offline-pendulum:bc-all,,dwbc -->",
         "record-glance offline-pendulum:bc-all,,dwbc: must be methods' names, A,B"),
        ("<!-- record-glance offline/pendulum -->", "'offline/pendulum' is not a record's name"),
        ("<!-- record-table pendulum-10seeds baseline=gail baseline=bc -->",
         "record-table has baseline= twice"),
    ],
)  # fmt: skip
def test_a_marker_the_program_cannot_read_is_refused(tmp_path, marker, message):
    """A misspelt kind, an option the kind does not take or whose value does not parse, a
    required option missing: each used to leave its table unmatched, silently unchecked."""
    kind = marker.split()[1].removeprefix("record-")
    page = _stale_page(tmp_path, f"before\n{marker}\n| old |\n<!-- /record-{kind} -->\n")
    before = page.read_bytes()
    with pytest.raises(run_records.RecordError, match=re.escape(f"results.md:2: {message}")):
        program.rewrite_docs(tmp_path, ROOT / "records")
    assert page.read_bytes() == before


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("| old |\n<!-- /record-table -->\n",
         "results.md:2: <!-- /record-table --> closes no marker (none is open)"),
        ("<!-- record-table pendulum-10seeds -->\n| old |\n<!-- /record-blocks -->\n",
         "results.md:3: <!-- /record-blocks --> cannot close the record-table marker of line 1"),
        ("<!-- record-table pendulum-10seeds -->\n<!-- record-glance pendulum-10seeds -->\n",
         "results.md:1: the record-table marker is not closed by <!-- /record-table --> "
         "before the next marker, on line 2"),  # nested
        ("<!-- record-table pendulum-10seeds -->\n| old |\n<!-- /record-table x -->\n",
         "results.md:3: a closing marker is <!-- /record-table -->, with nothing more"),
        ("  <!-- record-table pendulum-10seeds -->\n",
         "results.md:1: a record marker must stand alone on its line, unindented"),
        ("Text <!-- record-table pendulum-10seeds -->\n",
         "results.md:1: a record marker must stand alone on its line"),
        ("<!-- record-table pendulum-10seeds\n", "results.md:1: a record marker must end with"),
        ("<!-- record-table pendulum-10seeds --> | old |\n",
         "results.md:1: nothing may follow a record marker on its line"),
        ("```\n<!-- record-table pendulum-10seeds -->\n",
         "results.md:1: this code fence is never closed, and hides the record marker of line 2"),
    ],
)  # fmt: skip
def test_a_stray_or_misplaced_marker_is_refused(tmp_path, text, message):
    page = _stale_page(tmp_path, text)
    with pytest.raises(run_records.RecordError, match=re.escape(message)):
        program.rewrite_docs(tmp_path, ROOT / "records")
    assert page.read_text() == text


def test_a_good_page_is_rewritten_and_markers_in_prose_or_code_are_text(tmp_path, monkeypatch):
    """--docs rewrites a stale table between good markers and nothing else: a marker quoted
    in prose (even across lines) or shown in a fenced code block is text, not a marker."""
    prose = (
        "Between `<!-- record-table NAME -->` and `<!-- /record-table -->`; between `<!--\n"
        "record-seeds NAME turn=LEVEL -->` and `<!-- /record-seeds -->`.\n\n"
        "````markdown\n<!-- record-tabel x -->\n```\n<!-- /record-table -->\n````\n\n"
    )
    page = _stale_page(tmp_path, prose + STALE_COMPARISON + "\nafter\n")
    _run_docs(tmp_path, monkeypatch)
    table = program.comparison_record.table(
        program.comparison_record.check(ROOT / "records" / COMPARISON)
    )
    marker = f"<!-- record-comparison {COMPARISON} -->\n"
    assert page.read_text() == f"{prose}{marker}{table}\n<!-- /record-comparison -->\n\nafter\n"
    [(name, written, expected)] = program.marked_tables(page, ROOT / "records")
    assert name == COMPARISON and written == expected == table + "\n"
    before = page.stat().st_mtime_ns
    _run_docs(tmp_path, monkeypatch)
    assert page.stat().st_mtime_ns == before  # current: not written again


def test_a_record_that_fails_its_check_names_the_marker_and_nothing_is_written(tmp_path):
    """A well-formed marker whose record is missing: the record's error after the marker's
    file and line, and the README's stale table, whose record checks, is not written either
    (every table is computed before the first write)."""
    text = "x\n<!-- record-table no-such-record -->\n<!-- /record-table -->\n"
    page = _stale_page(tmp_path, text)
    (tmp_path / "README.md").write_text(STALE_COMPARISON)
    with pytest.raises(run_records.RecordError, match=r"results\.md:2: .*no-such-record"):
        program.rewrite_docs(tmp_path, ROOT / "records")
    assert page.read_text() == text and (tmp_path / "README.md").read_text() == STALE_COMPARISON


def test_every_records_command_runs_as_written():
    """Each committed record's stored command is ``python -m experiments.<program> ...`` of a
    program that exists, and that program's own parser takes its flags as written (a
    command that named ``python -m offline`` or a flag since renamed fails here)."""
    import importlib
    import json

    checked = 0
    for path in sorted((ROOT / "records").glob("*/record.json")):
        command = json.loads(path.read_text())["command"]
        assert command[:2] == ["python", "-m"] and command[2].startswith("experiments."), path
        program = importlib.import_module(
            "pngail_jax.programs." + command[2].removeprefix("experiments.")
        )
        assert (ROOT / "experiments" / f"{command[2].split('.')[1]}.py").is_file(), path
        program.build_parser().parse_args(command[3:])  # exits (a failure) on a bad flag
        checked += 1
    assert checked >= 20
