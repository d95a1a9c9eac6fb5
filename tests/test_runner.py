"""pngail_jax.runner: a whole run from Python, the same run the sweep program makes."""

from __future__ import annotations

import json
import os

import pytest
from conftest import metrics_numbers, tiny_sweep_args

from pngail_jax import RunConfig, RunError, run
from pngail_jax.programs import sweep


@pytest.fixture(scope="module")
def finished(demos_path, tmp_path_factory):
    """The tiny sweep, run by the program."""
    out = tmp_path_factory.mktemp("runs") / "run"
    sweep.main(tiny_sweep_args(demos_path, out))
    return out


def tiny_config(demos_path) -> RunConfig:
    """The RunConfig the sweep builds from ``tiny_sweep_args``."""
    return sweep.parse_args(tiny_sweep_args(demos_path, "unused")).config


def test_run_from_python_equals_the_sweep(finished, demos_path, tmp_path):
    out = tmp_path / "python"
    result = run(tiny_config(demos_path), out)
    assert result.out == out
    for path in result.files.values():
        assert path.exists(), path
    assert metrics_numbers(out / "metrics.csv") == metrics_numbers(finished / "metrics.csv")
    assert result.summary == json.loads((out / "summary.json").read_text())
    assert result.markdown == (out / "summary.md").read_text()
    # The table: one row per method, the summary's numbers.
    rows = {row["group"]: row for row in result.table()}
    assert set(rows) == {"gail", "pngail"}
    for group, row in rows.items():
        stats = result.summary["methods"][group]
        assert row["mean"] == stats["final_return_mean"]
        assert row["se"] == stats["final_return_se"]
        assert row["ci95"] == stats["final_return_ci95"]
        assert row["seeds"] == 2
    normalised = {row["group"]: row["iqm"] for row in result.table("final_normalized_return")}
    assert normalised == {
        group: stats["final_normalized_return_iqm"]
        for group, stats in result.summary["methods"].items()
    }
    with pytest.raises(KeyError, match="no metric 'final_reward'"):
        result.table("final_reward")
    recorded = json.loads((out / "config.json").read_text())["provenance"]["command_line"]
    assert "experiments.sweep" not in " ".join(recorded)  # the process that ran, not a program


def test_run_refuses_in_one_line_and_resumes_a_finished_run_without_work(
    finished, demos_path, tmp_path, capsys
):
    config = tiny_config(demos_path)
    with pytest.raises(RunError, match="already holds a run of experiments.sweep"):
        run(config, finished)
    with pytest.raises(RunError, match="give a RunConfig"):
        run(None, tmp_path / "new")
    assert not (tmp_path / "new").exists()  # refused before writing, no trace left
    other = config.replace(seeds=3)
    with pytest.raises(RunError, match="differs from the run's config.json"):
        run(other, finished, resume=True)
    relative = config.replace(demos=os.path.relpath(config.demos))  # as a user would type it
    assert run(relative, finished, resume=True).summary["complete"]  # the same config: goes on
    before = (finished / "metrics.csv").read_bytes()
    result = run(None, finished, resume=True)
    assert "already complete; nothing to do" in capsys.readouterr().out
    assert (finished / "metrics.csv").read_bytes() == before
    assert result.summary["complete"] and result.table()[0]["group"] == "gail"
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "notes.txt").write_text("mine")
    with pytest.raises(RunError, match="files it did not make"):
        run(config, occupied)
    assert [p.name for p in occupied.iterdir()] == ["notes.txt"]
