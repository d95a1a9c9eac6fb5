"""experiments.compare reading committed run records (records/NAME) beside run folders, and
picking methods of a source (PATH:A,B): the scores are the records' per-seed lists, pooled
and aggregated as NumPy does by hand; what cannot be pooled is refused in one line."""

import csv
import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_compare import refusal as run_refusal

from pngail_jax.analysis import compare, run_records
from pngail_jax.analysis.runs import sealed_part
from pngail_jax.programs import compare as program
from pngail_jax.storage.integrity import CONFIG_SEAL, seal
from pngail_jax.storage.outputs import prepare_output

RECORDS = Path(__file__).resolve().parent.parent / "records"
PENDULUM, HOPPER = RECORDS / "offline-pendulum", RECORDS / "offline-hopper"
PENDULUM_DWBC = RECORDS / "offline-pendulum-dwbc5000"


def per_seed(folder, method, statistic="late_average"):
    """float[seeds]: the record's own list of ``method``'s scores."""
    record = json.loads((folder / "record.json").read_text())
    return run_records.seed_values(record[run_records.statistic_key(statistic)][method])


def run_from_record(folder, directory, provenance="elsewhere"):
    """The offline run folder ``folder``'s record was made from, rebuilt: its config.json
    (the record's config with a provenance, sealed) and metrics.csv (the record's, unzipped)."""
    record = run_records.check_record(folder)
    prepare_output(directory, "offline")
    document = {**record["config"], "provenance": {"host": provenance}}
    (directory / "config.json").write_text(json.dumps(document))
    seal(directory / CONFIG_SEAL, sealed_part(document))
    with gzip.open(folder / run_records.METRICS_FILE, "rb") as source:
        (directory / "metrics.csv").write_bytes(source.read())
    return directory


def refusal(arguments, tmp_path, capsys) -> str:
    """The one line ``experiments.compare ARGUMENTS`` exits with (nothing written)."""
    message = run_refusal(arguments, tmp_path, capsys)
    assert message.strip().count("\n") == 0, message
    return message


@pytest.mark.parametrize("statistic", ["late_average", "final"])
def test_records_pooled_across_tasks_give_what_numpy_gives_of_their_seeds(
    statistic, tmp_path, capsys
):
    """Two tasks of five seeds each: the IQM pools all ten and cuts int(10 / 4) = 2 from each
    end; the mean is that of the two task means; P(ISW-BC > BC all) the mean over the tasks of
    the share of the 25 pairs ISW-BC wins (ties a half)."""
    sources = [f"{PENDULUM}:bc-all,iswbc", f"{HOPPER}:bc-all,iswbc"]
    options = ["--baseline", "bc-all", "--statistic", statistic, "--out", str(tmp_path / "c")]
    out = program.main([*sources, *options])
    result = json.loads((out / "compare.json").read_text())
    capsys.readouterr()
    assert result["tasks"] == ["Pendulum-v1", "Hopper-v4"]
    assert result["runs"] == sources
    ours = [per_seed(folder, "iswbc", statistic) for folder in (PENDULUM, HOPPER)]
    theirs = [per_seed(folder, "bc-all", statistic) for folder in (PENDULUM, HOPPER)]
    pooled = np.sort(np.concatenate(ours))
    assert pooled.size == 10 and np.isfinite(pooled).all()
    aggregates = result["aggregates"]["iswbc"]
    assert aggregates["iqm"]["estimate"] == pytest.approx(pooled[2:8].mean(), rel=1e-12)
    assert aggregates["mean"]["estimate"] == pytest.approx(
        np.mean([seeds.mean() for seeds in ours]), rel=1e-12
    )
    assert aggregates["optimality_gap"]["estimate"] == pytest.approx(
        1 - np.minimum(pooled, 1).mean(), rel=1e-12
    )
    wins = [
        ((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :])).mean()
        for a, b in zip(ours, theirs, strict=True)
    ]
    improvement = result["probability_of_improvement"]["iswbc"]
    assert improvement["estimate"] == pytest.approx(np.mean(wins), rel=1e-12)
    assert improvement["tasks"] == ["Pendulum-v1", "Hopper-v4"]
    assert result["seeds"]["iswbc"] == {"Pendulum-v1": 5, "Hopper-v4": 5}
    assert not result["unfinished"] and not result["notes"]


def test_a_pick_leaves_out_a_records_old_dwbc_and_its_own_record_brings_it():
    """offline-pendulum holds DWBC at the old setting: picked away, only the dwbc5000
    record's five seeds are DWBC's; without the pick both records' DWBC would pool to ten."""
    sources = [f"{PENDULUM}:bc-expert,bc-all,iswbc", f"{PENDULUM_DWBC}:dwbc"]
    picked = compare.load_scores([compare.parse_source(text) for text in sources])
    assert picked.methods == ["bc-expert", "bc-all", "iswbc", "dwbc"]
    assert picked.tasks == ["Pendulum-v1"]
    pendulum = picked.values["dwbc"]["Pendulum-v1"]
    np.testing.assert_array_equal(pendulum, per_seed(PENDULUM_DWBC, "dwbc"))
    np.testing.assert_array_equal(
        picked.values["bc-all"]["Pendulum-v1"], per_seed(PENDULUM, "bc-all")
    )
    whole = compare.load_scores([PENDULUM, PENDULUM_DWBC])  # two configs: their seeds pool
    np.testing.assert_array_equal(
        whole.values["dwbc"]["Pendulum-v1"],
        np.concatenate([per_seed(PENDULUM, "dwbc"), per_seed(PENDULUM_DWBC, "dwbc")]),
    )


def test_a_run_folder_made_from_a_record_compares_as_the_record_and_not_beside_it(tmp_path, capsys):
    """The same comparison on records and on the run folders they were made from gives the
    same numbers; a record and its run together are the same seeds twice: refused."""
    runs = [run_from_record(folder, tmp_path / folder.name) for folder in (PENDULUM, HOPPER)]
    from_records = program.main([str(PENDULUM), str(HOPPER), "--out", str(tmp_path / "a")])
    from_runs = program.main([*map(str, runs), "--out", str(tmp_path / "b")])
    capsys.readouterr()
    first, second = (
        json.loads((out / "compare.json").read_text()) for out in (from_records, from_runs)
    )
    for key in ("tasks", "seeds", "aggregates", "probability_of_improvement", "per_task"):
        assert first[key] == second[key], key
    mixed = program.main([str(runs[0]), f"{HOPPER}", "--out", str(tmp_path / "m")])  # mixed
    assert json.loads((mixed / "compare.json").read_text())["aggregates"] == first["aggregates"]
    message = refusal([PENDULUM, runs[0]], tmp_path, capsys)
    assert "the same seeds of the same config" in message and str(runs[0]) in message


def test_a_path_is_split_at_its_last_colon_only_before_method_names(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a:b").mkdir()
    assert compare.parse_source("a:b") == compare.Source(Path("a:b"))  # "a" does not exist
    assert compare.parse_source("a:b:x,y.1+z") == compare.Source(Path("a:b"), ("x", "y.1+z"))
    assert compare.parse_source("a:b:x y") == compare.Source(Path("a:b:x y"))  # no names
    assert compare.parse_source("a:b:x,") == compare.Source(Path("a:b:x,"))
    assert compare.parse_source("missing:x") == compare.Source(Path("missing:x"))
    assert str(compare.parse_source("a:b:x,y")) == "a:b:x,y"


def test_each_refusal_is_one_line_naming_the_problem(tmp_path, capsys):
    assert "is given twice" in refusal([PENDULUM, PENDULUM], tmp_path, capsys)
    message = refusal([f"{PENDULUM}:bc-all", f"{PENDULUM}:iswbc"], tmp_path, capsys)
    assert "is given twice" in message and "PATH:A,B picks several" in message
    copy = tmp_path / "copy"
    shutil.copytree(PENDULUM, copy)
    assert "the same seeds of the same config" in refusal([PENDULUM, copy], tmp_path, capsys)
    assert f"{PENDULUM} has no method 'gail' (it has bc-expert, bc-all, dwbc, iswbc)" in refusal(
        [f"{PENDULUM}:bc-all,gail"], tmp_path, capsys
    )
    record = json.loads((copy / "record.json").read_text())
    record["late_average_normalized_return"]["bc-all"][0] += 0.5  # a better seed, by hand
    (copy / "record.json").write_text(json.dumps(record))
    assert "was changed since it was written" in refusal([copy], tmp_path, capsys)
    shutil.copy(PENDULUM / "record.json", copy / "record.json")
    (copy / run_records.METRICS_FILE).write_bytes(b"\x1f\x8b damaged")
    assert "differs from what the record wrote" in refusal([copy], tmp_path, capsys)
    assert "is a record of experiments.compare_settings" in refusal(
        [RECORDS / "settings-ant-v4"], tmp_path, capsys
    )
    assert "is not a directory" in refusal([tmp_path / "nowhere:bc-all"], tmp_path, capsys)
    message = refusal([PENDULUM, "--expected", PENDULUM_DWBC], tmp_path, capsys)
    assert f"--expected sets runs against a record: {PENDULUM} is a record itself" in message


def test_an_unfinished_record_is_compared_and_named_as_an_unfinished_run_is(tmp_path, capsys):
    """A record of an offline run stopped halfway (25 of 50 iterations) is read to its
    latest evaluation and named at the top of compare.md, as an unfinished run folder is."""
    cut = run_from_record(PENDULUM_DWBC, tmp_path / "cut")
    rows = list(csv.DictReader((cut / "metrics.csv").open()))
    with (cut / "metrics.csv").open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(row for row in rows if int(row["iteration"]) <= 25)
    config = {**json.loads((cut / "config.json").read_text()), "complete": False}
    (cut / "config.json").write_text(json.dumps(config))
    seal(cut / CONFIG_SEAL, sealed_part(config))
    (cut / "summary.json").write_text(json.dumps({"complete": False}))
    folder = run_records.write_record(cut, "cut", tmp_path / "records")
    scores = compare.load_scores([folder])
    assert scores.unfinished == {str(folder): "25 of 50 iterations"}
    np.testing.assert_array_equal(scores.values["dwbc"]["Pendulum-v1"], per_seed(folder, "dwbc"))
    out = program.main([str(folder), "--out", str(tmp_path / "c")])
    assert (
        f"**Unfinished runs**, read up to their latest evaluation so far: {folder} (25 of 50 "
        in ((out / "compare.md").read_text())
    )
    capsys.readouterr()
