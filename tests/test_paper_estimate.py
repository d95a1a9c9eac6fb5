"""The paper plan's wall-time estimate (``pngail_jax.paper.estimate``): a grid's steps over
the measured rate of the row nearest its cell count, plus that row's compile; printed by
``experiments.paper --throughput`` before anything runs."""

import json

import pytest

from pngail_jax.jobs.chunks import format_seconds
from pngail_jax.jobs.errors import RunError
from pngail_jax.paper import estimate
from pngail_jax.programs import paper

ROWS = [
    {"env": "Pendulum-v1", "cells": 1, "steps_per_second": 100.0, "status": "ok"},
    {"env": "Pendulum-v1", "cells": 14, "steps_per_second": 5000.0,
     "steps_per_second_with_eval": 1120.0, "compile_seconds": 5.0, "status": "ok"},
    {"env": "Hopper-v4", "cells": 35, "status": "timed out after 30 s"},
    {"env": "Hopper-v4", "cells": 35, "physics": "mjx", "steps_per_second": 9.0e5},
    {"env": "Hopper-v4", "cells": 35, "physics": "warp", "steps_per_second": 2.0e6},
]  # fmt: skip


def test_the_nearest_row_of_the_plans_engine_is_read(tmp_path):
    path = tmp_path / "rows.json"
    path.write_text(json.dumps(ROWS))
    rows = estimate.read_throughput(path)
    assert len(rows) == 4  # the timed-out row is left out
    assert estimate.nearest_row(rows, "Pendulum-v1", None, 3)["cells"] == 1  # log scale
    assert estimate.nearest_row(rows, "Pendulum-v1", None, 7)["cells"] == 14
    assert estimate.nearest_row(rows, "Hopper-v4", "warp", 35)["steps_per_second"] == 2.0e6
    assert estimate.nearest_row(rows, "Hopper-v4", "mjx", 35)["steps_per_second"] == 9.0e5
    assert estimate.nearest_row(rows, "Walker2d-v4", "mjx", 35) is None
    path.write_text("{not json")
    with pytest.raises(RunError, match="--throughput .*rows.json: cannot be read"):
        estimate.read_throughput(path)
    path.write_text(json.dumps([{"env": "Pendulum-v1", "cells": 1, "status": "failed: x"}]))
    with pytest.raises(RunError, match="no row with a task, cells and a training rate"):
        estimate.read_throughput(path)


def test_the_plan_prints_its_estimate_before_it_makes_anything(tmp_path, monkeypatch, capsys):
    """Fig. 2 on Pendulum-v1 at the test preset: one grid of 7 methods x 2 seeds (14 cells)
    x 4 iterations x 4 envs x 50 steps = 11,200 steps at the 14-cell row's 1,120 steps/s
    with evaluation, plus its 5 s compile: 15 s; the made demonstrations, 1 seed x 4
    iterations x 200 steps at the 1-cell row's 100 steps/s: 8 s."""
    from pngail_jax.paper import run

    def stop(*args, **kwargs):
        raise KeyboardInterrupt  # right after the estimate: nothing is made or run

    monkeypatch.setattr(run, "demo_paths", stop)
    rows = tmp_path / "rows.json"
    rows.write_text(json.dumps(ROWS))
    out = tmp_path / "plan"
    argv = ["--preset", "test", "--only", "fig2", "--envs", "Pendulum-v1", "--out", str(out)]
    with pytest.raises(SystemExit, match="interrupted"):
        paper.main([*argv, "--throughput", str(rows)])
    printed = capsys.readouterr().out
    grid = f"| Pendulum-v1-main | Pendulum-v1 | 14 | 11,200 | 1,120 (14) | {format_seconds(15)} |"
    assert grid in printed
    assert "| demonstrations of Pendulum-v1 | Pendulum-v1 | 1 | 800 | 100 (1) | " in printed
    assert f"about {format_seconds(23)} in all" in printed
    with pytest.raises(SystemExit, match="interrupted"):  # what is left, on a resume
        paper.main(["--resume", str(out), "--throughput", str(rows)])
    assert "Pendulum-v1-main" in capsys.readouterr().out
    bad = tmp_path / "bad.json"
    bad.write_text("[]")
    with pytest.raises(SystemExit, match="--throughput .*bad.json: no row"):
        paper.main(["--resume", str(out), "--throughput", str(bad)])
