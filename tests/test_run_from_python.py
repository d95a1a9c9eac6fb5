"""run(config, out): a whole run from Python (pngail_jax.jobs.sweep), the same run the sweep
program makes."""

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
    rows = {row["group"]: row for row in result.table()}  # the headline by default
    assert set(rows) == {"gail", "pngail"}
    for group, row in rows.items():
        stats = result.summary["methods"][group]
        assert row["mean"] == stats["late_average_normalized_return_mean"]
        assert row["se"] == stats["late_average_normalized_return_se"]
        assert row["ci95"] == stats["late_average_normalized_return_ci95"]
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


def test_a_grid_axis_keys_the_csv_the_summary_and_the_policies(finished, demos_path, tmp_path):
    """--grid max_kl=0.005,0.01 on the tiny sweep: one column and one summary row per value;
    its max_kl=0.01 cells are the tiny sweep's (0.01 is the default), to the float tolerance
    of two programs (tests/test_grid.py's: 1e-3 relative for returns and KL)."""
    import csv

    import numpy as np

    argv = [*tiny_sweep_args(demos_path, tmp_path / "axis"), "--grid", "max_kl=0.005,0.01"]
    sweep.main(argv)
    out = tmp_path / "axis"
    with open(out / "metrics.csv") as file:
        rows = list(csv.DictReader(file))
    assert {row["max_kl"] for row in rows} == {"0.005", "0.01"}
    default = [
        {k: v for k, v in row.items() if k not in ("wall_seconds", "setting", "max_kl")}
        for row in rows
        if row["max_kl"] == "0.01"
    ]
    alone = [
        {k: v for k, v in row.items() if k != "setting"}
        for row in metrics_numbers(finished / "metrics.csv")
    ]
    assert len(default) == len(alone)
    for ours, theirs in zip(default, alone, strict=True):
        assert ours.keys() == theirs.keys()
        for key, value in ours.items():
            if key in ("method", "seed", "iteration", "env_steps") or not value:
                assert value == theirs[key], key
            else:
                atol = 1e-3 if key == "normalized_return" else 0.0  # a value near 0
                np.testing.assert_allclose(
                    float(value), float(theirs[key]), rtol=1e-3, atol=atol, err_msg=key
                )
    groups = json.loads((out / "summary.json").read_text())["methods"]
    assert len(groups) == 4 and "pngail [label_ratio=0.2,noise=0,max_kl=0.005]" in groups
    policies = out / "policies" / "gail" / "label_ratio=0.2,noise=0,max_kl=0.005" / "policy.json"
    assert policies.exists()
    config = json.loads((out / "config.json").read_text())
    assert config["config"]["grid_axes"] == [["max_kl", [0.005, 0.01]]]


def test_a_registered_method_resumes_from_its_record(demos_path, tmp_path, capsys):
    """A method given to ``methods.register`` in the process that began a run is registered
    again from the run's config.json when another process resumes it."""
    from pngail_jax.adversarial.methods import PRESETS, Preset, preset_record, register

    mine = Preset("GAIL at half the agent weight", "none", {"agent_coef": 0.5, "gail_coef": 1.0})
    out = tmp_path / "run"
    try:
        register("gail-half", mine)
        recorded = preset_record("gail-half")
        run(tiny_config(demos_path).replace(methods=("gail-half",), seeds=1), out)
    finally:
        PRESETS.pop("gail-half", None)
    try:
        result = run(None, out, resume=True)  # as a new process, which never registered it
        assert "registered again from the run's config.json" in capsys.readouterr().out
        assert result.summary["complete"] and preset_record("gail-half") == recorded
        register("gail-half", mine)  # the same method under its own description: accepted
        with pytest.raises(ValueError, match="already registered as another method"):
            register("gail-half", Preset("other", "none", {"agent_coef": 0.25}))
    finally:
        PRESETS.pop("gail-half", None)


def test_a_long_chunk_says_when_it_should_end_at_the_pace_so_far():
    from pngail_jax.jobs.chunks import LONG_CHUNK_SECONDS, Progress, long_chunk_notice

    def progress(seconds, chunks_done=2):
        return Progress(chunks_done, {}, None, {"seconds": seconds, "steps": 0})

    # The first chunk has no pace to go by, and a short chunk gets its progress line soon.
    assert long_chunk_notice(progress(0.0, chunks_done=0), 5, 100) is None
    assert long_chunk_notice(progress(2 * LONG_CHUNK_SECONDS - 2), 5, 100) is None
    line = long_chunk_notice(progress(2 * 3720.0), 5, 100)
    assert "chunk 3/5 (iterations 201-300)" in line and "62m00s a chunk" in line
