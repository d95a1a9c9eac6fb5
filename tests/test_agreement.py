"""experiments.agreement: each statistic of a run's seeds scored by split-half agreement."""

import csv
import json

import numpy as np
import pytest
from conftest import as_sweep_run

from pngail_jax.analysis.report import write_metrics_csv
from pngail_jax.grid import make_cells
from pngail_jax.programs import agreement


def _run(tmp_path, num_seeds: int):
    """A metrics.csv of two methods whose final evaluation is noise but whose late evaluations
    separate them: 'good' ends at 0.8 +- 0.02, 'bad' at 0.2 +- 0.02, with one last wild
    evaluation (+-0.5) in every seed."""
    rng = np.random.default_rng(0)
    cells = make_cells(["good", "bad"], num_seeds)
    returns = np.full((len(cells), 20), np.nan)
    for index, cell in enumerate(cells):
        level = 0.8 if cell.method == "good" else 0.2
        returns[index, 1::2] = level + 0.02 * rng.normal(size=10)
        returns[index, -1] = 0.5 + rng.uniform(-0.5, 0.5)
    metrics = {"eval/return": returns, "env_steps": np.tile(np.arange(1, 21), (len(cells), 1))}
    write_metrics_csv(tmp_path / "metrics.csv", cells, metrics, (0.0, 1.0))
    return as_sweep_run(tmp_path, (0.0, 1.0))


def test_late_means_agree_where_the_final_evaluation_does_not(tmp_path, capsys):
    run = _run(tmp_path, num_seeds=8)
    rows = agreement.main([str(run), "--lasts", "1,5", "--splits", "500",
                           "--json", str(tmp_path / "a.json")])  # fmt: skip
    by_name = {row["statistic"]: row for row in rows}
    assert set(by_name) == {
        "final evaluation", "mean of the last 5", "last 20% of training, the headline (2 "
        "evaluations)", "all of training"
    }  # fmt: skip
    assert by_name["mean of the last 5"]["same_best"] == 1.0
    assert by_name["mean of the last 5"]["kendall_tau"] == 1.0
    assert by_name["final evaluation"]["same_best"] < 0.9
    assert by_name["mean of the last 5"]["mean_abs_difference"] < 0.1
    assert json.loads((tmp_path / "a.json").read_text()) == rows
    with pytest.raises(SystemExit, match="^2$"):  # never over a file it did not make
        agreement.main([str(run), "--json", str(tmp_path / "a.json")])
    assert f"--json {tmp_path / 'a.json'} exists: choose another file" in capsys.readouterr().err
    assert agreement.main([str(run), "--splits", "10", "--json", str(tmp_path / "a.json"),
                           "--overwrite"])  # fmt: skip
    assert "| final evaluation |" in capsys.readouterr().out


def test_too_few_seeds_and_no_run_are_one_line(tmp_path, capsys):
    run = _run(tmp_path, num_seeds=3)
    with pytest.raises(SystemExit, match="fewer than 4 seeds"):
        agreement.main([str(run)])
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        agreement.main([str(tmp_path / "nothing")])
    assert f"{tmp_path / 'nothing'}: no metrics.csv there (not a sweep run or record)" in (
        capsys.readouterr().err
    )


def test_a_run_or_record_is_verified_before_it_is_read(tmp_path, capsys):
    """agreement trusts a run only as every program does (runs.verify_run): a normalised
    return edited by hand is refused in one line; a committed record is checked, then read."""
    from pathlib import Path

    run = _run(tmp_path, num_seeds=4)
    with (run / "metrics.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    evaluated = next(row for row in rows if row["eval_return"])
    evaluated["normalized_return"] = "0.99"  # edited alone
    with (run / "metrics.csv").open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        agreement.main([str(run)])
    assert (
        f"{run / 'metrics.csv'}: good seed 0 iteration 2: normalised return 0.99 is not its "
        "evaluation"
    ) in capsys.readouterr().err
    record = Path(__file__).parents[1] / "records" / "pendulum-10seeds"
    rows = agreement.main([str(record), "--splits", "10"])
    assert rows and "pendulum-10seeds" in capsys.readouterr().out
