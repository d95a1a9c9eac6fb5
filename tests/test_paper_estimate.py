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
    # gpu_check's other rows: a step with no time left, and an environment-only measurement
    {"step": "training", "engine": "mjx", "task": "Ant-v4", "status": "skipped: no time left"},
    {"step": "env only", "name": "env_step", "env": "Hopper-v4", "width": 875,
     "steps_per_second": 3.0e7, "compile_seconds": None, "status": "ok"},
]  # fmt: skip


def test_the_nearest_row_of_the_plans_engine_is_read(tmp_path):
    path = tmp_path / "rows.json"
    path.write_text(json.dumps(ROWS))
    rows = estimate.read_throughput(path)
    assert len(rows) == 4  # the timed-out, skipped and environment-only rows are left out
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
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        paper.main(["--resume", str(out), "--throughput", str(bad)])
    assert f"--throughput {bad}: no row with a task, cells and a training rate" in (
        capsys.readouterr().err
    )


GOOD = {"env": "Pendulum-v1", "cells": 14, "steps_per_second": 5000.0, "compile_seconds": 5.0}
MISSING = object()  # the field left out of the row

# {case: (the fields of GOOD changed in the file's second row, what the line says after
# "row 2 (Pendulum-v1): ")}; json.dumps writes NaN and Infinity as Python's json reads them
BAD_FIELDS = {
    "negative compile": ({"compile_seconds": -3.1}, "compile_seconds -3.1 is negative"),
    "zero rate": ({"steps_per_second": 0}, "steps_per_second 0 is not above 0"),
    "negative rate": ({"steps_per_second_with_eval": -5.0},
                      "steps_per_second_with_eval -5.0 is negative"),
    "NaN rate": ({"steps_per_second": float("nan")}, "steps_per_second NaN is not finite"),
    "infinite rate": ({"steps_per_second": float("inf")},
                      "steps_per_second Infinity is not finite"),
    "infinite compile": ({"compile_seconds": float("-inf")},
                         "compile_seconds -Infinity is not finite"),
    "huge whole compile": ({"compile_seconds": 10**400}, "compile_seconds 1000"),
    "string rate": ({"steps_per_second": "fast"}, 'steps_per_second "fast" is not a number'),
    "string compile": ({"compile_seconds": "5"}, 'compile_seconds "5" is not a number'),
    "boolean rate": ({"steps_per_second": True}, "steps_per_second true is not a number"),
    "boolean cells": ({"cells": True}, "cells true is not a whole number above 0"),
    "zero cells": ({"cells": 0}, "cells 0 is not a whole number above 0"),
    "fractional cells": ({"cells": 3.5}, "cells 3.5 is not a whole number above 0"),
    "string cells": ({"cells": "14"}, 'cells "14" is not a whole number above 0'),
    "missing cells": ({"cells": MISSING}, "cells is missing"),
    "missing rate": ({"steps_per_second": MISSING}, "no training rate: "
                     "steps_per_second_with_eval or steps_per_second is missing"),
    "null rate": ({"steps_per_second": None}, "no training rate"),
    "unknown engine": ({"physics": "gpu"}, 'physics "gpu" is not an engine (c, mjx, warp)'),
    "status not a string": ({"status": 0}, "status 0 is not a string"),
}  # fmt: skip

BAD_ROWS = {  # {case: (the file's second row, what the line says of it)}
    "missing task": ({"cells": 14, "steps_per_second": 5000.0},
                     "row 2: env (the task) is missing"),
    "unknown task": ({**GOOD, "env": "Hoper-v4"},
                     'row 2: env "Hoper-v4" is not a known task (Pendulum-v1, Hopper-v4, '),
    "task not a string": ({**GOOD, "env": 7}, "row 2: env 7 is not a known task"),
    "a number": (5, "row 2: 5 is not a JSON object"),
    "a list": (["Pendulum-v1", 14], 'row 2: ["Pendulum-v1", 14] is not a JSON object'),
    **{case: ({name: value for name, value in ({**GOOD, **fields}).items()
               if value is not MISSING}, f"row 2 (Pendulum-v1): {said}")
       for case, (fields, said) in BAD_FIELDS.items()},
}  # fmt: skip

BAD_FILES = {  # (the whole file's text, what the one line says of it)
    "empty list": ("[]", "no row with a task, cells and a training rate"),
    "not a list": (json.dumps({"rows": [GOOD]}), "not a benchmark's rows (a JSON list), got {"),
    "a bare number": ("3.5", "not a benchmark's rows (a JSON list), got 3.5"),
    "not JSON": ("{not json", "cannot be read (Expecting property name"),
    "only failed rows": (json.dumps([{**GOOD, "status": "failed: x"}]), "no row with a task"),
}


def refused_before_anything_is_made(tmp_path, monkeypatch, capsys, text: str) -> str:
    """The plan's program given a throughput file holding ``text``: asserts it exits with one
    line on stderr and leaves no --out folder behind, and returns that line."""
    from pngail_jax.paper import run

    def stop(*args, **kwargs):
        raise KeyboardInterrupt  # were the file let through: stop before anything runs

    monkeypatch.setattr(run, "demo_paths", stop)
    path = tmp_path / "rows.json"
    if text is not None:
        path.write_text(text)
    out = tmp_path / "plan"
    argv = ["--preset", "test", "--only", "fig2", "--envs", "Pendulum-v1", "--out", str(out)]
    with pytest.raises(SystemExit) as exit_info:
        paper.main([*argv, "--throughput", str(path)])
    assert exit_info.value.code == 2  # parser.error's, in the argument checks
    assert not out.exists()
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert f"error: --throughput {path}: " in lines[0]
    return lines[0]


@pytest.mark.parametrize("row, message", BAD_ROWS.values(), ids=BAD_ROWS.keys())
def test_a_bad_row_is_one_line_naming_it_before_anything_is_made(
    row, message, tmp_path, monkeypatch, capsys
):
    text = json.dumps([GOOD, row])
    assert message in refused_before_anything_is_made(tmp_path, monkeypatch, capsys, text)


@pytest.mark.parametrize("text, message", BAD_FILES.values(), ids=BAD_FILES.keys())
def test_a_bad_file_is_one_line_before_anything_is_made(
    text, message, tmp_path, monkeypatch, capsys
):
    assert message in refused_before_anything_is_made(tmp_path, monkeypatch, capsys, text)


def test_a_missing_file_is_one_line_before_anything_is_made(tmp_path, monkeypatch, capsys):
    line = refused_before_anything_is_made(tmp_path, monkeypatch, capsys, None)
    assert "rows.json: cannot be read ([Errno 2] No such file or directory" in line


def test_null_means_not_measured_and_each_rate_given_is_checked(tmp_path):
    """compile_seconds null counts 0 s; a null rate falls back to the next one; a bad rate
    is refused even where the other one (which the estimate would read first) is good."""
    path = tmp_path / "rows.json"
    row = {**GOOD, "compile_seconds": None, "steps_per_second_with_eval": None}
    path.write_text(json.dumps([row]))
    (read,) = estimate.read_throughput(path)
    assert estimate._seconds(read, 10_000) == 2.0  # 10,000 steps at 5,000 steps/s, no compile
    path.write_text(json.dumps([{**GOOD, "steps_per_second_with_eval": 1000.0,
                                 "steps_per_second": -1.0}]))  # fmt: skip
    with pytest.raises(RunError, match=r"row 1 \(Pendulum-v1\): steps_per_second -1.0 is neg"):
        estimate.read_throughput(path)
