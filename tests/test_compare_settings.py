"""compare_settings: each arm is the train_rl run its flags give, and the verdict is the one
docs/performance.md states (not worse: mean >= the baseline's mean - 1 s.e., each arm on the
physics it trained on)."""

import json
import math

import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.config.validation import ConfigError
from pngail_jax.jobs import compare_settings as job
from pngail_jax.jobs.train_rl import TrainRLConfig
from pngail_jax.programs import train_rl
from pngail_jax.programs.cli import config_from
from pngail_jax.storage import outputs


@pytest.mark.parametrize("arm", sorted(job.ARMS))
def test_each_arm_is_the_train_rl_run_of_its_flags(arm, tmp_path):
    config = job.CompareSettingsConfig(env="Hopper-v4", arms=(arm,), iterations=100, seeds=2)
    flags = [
        *("--env", "Hopper-v4", "--seeds", "2", "--seed", "0", "--iterations", "100"),
        *("--eval-every", "50", "--fisher", "gauss_newton", "--out", str(tmp_path / arm)),
        *job.arm_flags(arm),
    ]
    assert config.arm_config(arm) == config_from(TrainRLConfig, train_rl.parse_args(flags))


def test_arms_are_checked_in_one_line():
    with pytest.raises(ConfigError, match="unknown arm 'fastest'"):
        job.CompareSettingsConfig(env="Hopper-v4", arms=("table", "fastest"))
    with pytest.raises(ConfigError, match="'table' is not among the arms"):
        job.CompareSettingsConfig(env="Hopper-v4", arms=("reference",), baseline="table")
    with pytest.raises(ConfigError, match="Pendulum-v1 has no MJX solver"):
        job.CompareSettingsConfig(env="Pendulum-v1", arms=("reference-fast",))
    assert job.CompareSettingsConfig(env="Hopper-v4", arms=("table", "reference")).baseline == (
        "table"
    )


def _result(final_own, final_fast=None, env_options=None):
    arrays = {"own": np.asarray(final_own, float)}
    if final_fast is not None:
        arrays["fast"] = np.asarray(final_fast, float)
    return {
        "rollout": {"num_envs": 25, "unroll_length": 200, "normalize_observations": False},
        "env_options": env_options or {},
        "fisher_subsample": 1,
        "final_return": {k: v.tolist() for k, v in arrays.items()},
        "final_return_mean_se": {k: job.mean_and_standard_error(v) for k, v in arrays.items()},
        "average_eval_return_mean_se": (0.0, 0.0),
    }


def test_the_verdict_is_mean_at_least_the_baselines_mean_minus_one_standard_error(tmp_path):
    """The baseline (own solver) has mean 100, s.e. 10: an arm at 91 is not worse, one at 89
    is; an arm trained on the fast solver is judged by its fast-solver returns."""
    config = job.CompareSettingsConfig(env="Hopper-v4", arms=("table", "reference", "wide-fast"))
    assert job.mean_and_standard_error([90, 110]) == (100.0, 10.0)
    results = {
        "table": _result([90, 110]),
        "reference": _result([89, 89]),
        "wide-fast": _result([0, 0], [91, 91], env_options=dict(envs.FAST_SOLVER)),
    }
    steps = np.array([10, 20])
    curves = {arm: (steps, np.ones((2, 2))) for arm in results}
    summary = job.write_comparison(config, tmp_path, results, curves)
    verdicts = {arm: r["not_worse_than_baseline"] for arm, r in summary["arms"].items()}
    assert verdicts == {"table": True, "reference": False, "wide-fast": True}
    assert summary["arms"]["wide-fast"]["trained_on"] == "fast"
    saved = json.loads((tmp_path / job.COMPARISON_FILE).read_text())
    assert saved["arms"]["reference"]["not_worse_than_baseline"] is False
    markdown = (tmp_path / "comparison.md").read_text()
    assert "| reference | 25 x 200, own solver | 89.0 ± 0.0 |" in markdown
    assert "| NO |" in markdown


def test_an_arm_between_the_fast_caps_and_the_own_ones_is_judged_on_the_own_physics():
    """4 / 16 is neither physics the final evaluation runs: its verdict reads the task's own
    (the physics its caps approximate), the fast caps' reads the fast one, Ant's always
    the fast one (its own caps are the fast ones)."""
    middle = job.CompareSettingsConfig(env="Hopper-v4", arms=("reference-solver-4-16",))
    options = middle.arm_config("reference-solver-4-16").settings
    assert (options.solver_iterations, options.ls_iterations) == (4, 16)
    assert job.trained_on("Hopper-v4", {"solver_iterations": 4, "ls_iterations": 16}) == "own"
    assert job.trained_on("Hopper-v4", dict(envs.FAST_SOLVER)) == "fast"
    assert job.trained_on("Hopper-v4", {}) == "own"
    assert job.trained_on("Ant", {}) == "fast"


def test_one_seed_has_no_standard_error():
    mean, se = job.mean_and_standard_error([3.0])
    assert mean == 3.0 and math.isnan(se)


def test_the_job_trains_evaluates_and_reuses_a_finished_arm(tmp_path, capsys, monkeypatch):
    """The whole job on one Pendulum-v1 arm, one iteration: the arm is a train_rl run, its
    policies are evaluated again on fresh keys, and a second call reuses the finished arm. The
    output path is relative, as on a command line (orbax restores absolute paths only)."""
    config = job.CompareSettingsConfig(
        env="Pendulum-v1", arms=("table",), seeds=2, iterations=1, eval_every=1,
        num_eval_episodes=2,
    )  # fmt: skip
    monkeypatch.chdir(tmp_path)
    summary = job.compare_settings(config, "cmp")
    arm = summary["arms"]["table"]
    assert len(arm["final_return"]["own"]) == 2 and "fast" not in arm["final_return"]
    assert arm["rollout"] == {"num_envs": 25, "unroll_length": 200, "normalize_observations": False}
    assert arm["not_worse_than_baseline"] is True  # the baseline itself
    assert (tmp_path / "cmp" / "table" / "policy.json").exists()
    assert outputs.unaccounted(tmp_path / "cmp", "compare_settings") == []
    assert all(outputs.unaccounted(tmp_path / "cmp" / arm, "train_rl") == [] for arm in ("table",))
    again = job.compare_settings(config, tmp_path / "cmp", overwrite=True)
    assert "table: finished run in" in capsys.readouterr().out
    assert again["arms"]["table"]["final_return"] == arm["final_return"]  # same keys, same policies


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A finished two-arm Pendulum-v1 comparison (one iteration) and its record."""
    from pngail_jax.programs import record as record_program

    tmp_path = tmp_path_factory.mktemp("recorded")
    config = job.CompareSettingsConfig(
        env="Pendulum-v1", arms=("table", "reference-fisher5"), seeds=2, iterations=1,
        eval_every=1, num_eval_episodes=2,
    )  # fmt: skip
    summary = job.compare_settings(config, tmp_path / "cmp", command=["--env", "Pendulum-v1"])
    records = tmp_path / "records"
    record_program.main([str(tmp_path / "cmp"), "--name", "cmp", "--records", str(records)])
    return tmp_path, summary, records


def test_a_finished_comparison_is_recorded_and_its_table_rendered(recorded):
    """The comparison keeps its command, commit and curves; ``experiments.record`` makes a
    record of it whose table is the comparison's own, and a docs marker is rewritten to it."""
    from pngail_jax.jobs import comparison_record
    from pngail_jax.programs import record as record_program

    tmp_path, summary, records = recorded
    command = summary["provenance"]["command_line"]
    assert command[:3] == ["python", "-m", "experiments.compare_settings"]
    assert summary["provenance"]["arms_reused"] == []
    assert np.asarray(summary["curves"]["table"]["eval_return"]).shape == (2, 1)
    record = comparison_record.check(records / "cmp")
    rendered = comparison_record.table(record) + "\n"
    assert rendered == (tmp_path / "cmp" / "comparison.md").read_text()
    assert "compare_settings on Pendulum-v1" in comparison_record.describe(record)
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("no tables\n")
    page = tmp_path / "docs" / "performance.md"
    page.write_text("<!-- record-comparison cmp -->\n| stale |\n<!-- /record-comparison -->\n")
    assert record_program.rewrite_docs(tmp_path, records) == [page]
    ((name, written, expected),) = record_program.marked_tables(page, records)
    assert name == "cmp" and written == expected == rendered
    one_seed = json.loads(json.dumps(record))  # one seed: no standard error, JSON null
    one_seed["comparison"]["arms"]["table"]["final_return_mean_se"]["own"][1] = None
    assert "± nan" in comparison_record.table(one_seed)


def test_a_comparison_records_check_recomputes_every_figure_of_its_table(recorded):
    """Each figure the table shows, edited in the record, fails the check, naming it; a
    record missing a part, a bad name and a comparison from before provenance are refused."""
    from pngail_jax.analysis.run_records import RecordError
    from pngail_jax.jobs import comparison_record
    from pngail_jax.programs import record as record_program

    tmp_path, _, records = recorded
    kept = json.loads((records / "cmp" / "record.json").read_text())
    comparison_record.verify(kept, "kept")

    def edited(change):
        record = json.loads(json.dumps(kept))
        change(record["comparison"]["arms"]["table"], record["comparison"])
        comparison_record.verify(record, "edited")

    def seed_curve(comparison):
        return comparison["curves"]["table"]["eval_return"][0]

    edits = {
        "final return on the own solver": lambda a, _: a["final_return"]["own"].__setitem__(0, 1),
        "physics trained on": lambda arm, _: arm.__setitem__("trained_on", "fast"),
        "verdict": lambda arm, _: arm.__setitem__("not_worse_than_baseline", False),
        "set of physics": lambda arm, _: arm["final_return"].__setitem__("fast", [0.0, 0.0]),
        "count of seeds or steps": lambda _, comparison: comparison.__setitem__("seeds", 3),
        "average during training": lambda _, c: seed_curve(c).__setitem__(0, 9.0),
    }  # fmt: skip
    for problem, change in edits.items():
        with pytest.raises(RecordError, match=f"arm table's {problem} differs"):
            edited(change)
    with pytest.raises(RecordError, match="not a whole comparison record"):
        edited(lambda arm, _: arm.pop("final_return"))
    with pytest.raises(SystemExit, match="plain folder name"):
        record_program.main([str(tmp_path / "cmp"), "--name", "../x", "--records", str(records)])
    old = json.loads((tmp_path / "cmp" / job.COMPARISON_FILE).read_text())
    del old["provenance"]
    (tmp_path / "before").mkdir()
    (tmp_path / "before" / job.COMPARISON_FILE).write_text(json.dumps(old))
    (tmp_path / "before" / ".pngail-run.json").write_text(
        (tmp_path / "cmp" / ".pngail-run.json").read_text()
    )
    with pytest.raises(SystemExit, match="run its compare_settings command again"):
        record_program.main(
            [str(tmp_path / "before"), "--name", "other", "--records", str(records)]
        )


def _contrast_record(env, finals_by_arm, env_options_by_arm):
    arms = {}
    for arm, finals in finals_by_arm.items():
        result = _result(finals, finals, env_options=env_options_by_arm.get(arm))
        result["average_eval_return_mean_se"] = (float(np.mean(finals)) / 2, 1.0)
        arms[arm] = result
    return {"comparison": {"env": env, "arms": arms}}


def test_a_contrast_table_puts_each_tasks_arms_beside_its_baseline_on_the_own_physics():
    """Each row's mean ± s.e. and P(arm > baseline) against NumPy on the per-seed finals
    (every pair of seeds, ties counting a half); arms a comparison lacks are left out."""
    from pngail_jax.jobs import comparison_record

    rng = np.random.default_rng(3)
    hopper = {"reference": rng.normal(100, 10, 5), "reference-fast": rng.normal(110, 10, 5)}
    hopper["reference-fast"][0] = hopper["reference"][0]  # a tie
    swimmer = {"reference": rng.normal(30, 3, 5), "reference-solver-4-16": rng.normal(20, 3, 5)}
    options = {"reference-fast": dict(envs.FAST_SOLVER),
               "reference-solver-4-16": {"solver_iterations": 4, "ls_iterations": 16}}  # fmt: skip
    records = [_contrast_record("Hopper-v4", hopper, options),
               _contrast_record("Swimmer-v4", swimmer, options)]  # fmt: skip
    table = comparison_record.contrast_table(
        records, ["reference-solver-4-16", "reference-fast"], "reference"
    )
    rows = [line.split(" | ") for line in table.splitlines()[2:]]
    assert [(row[0], row[1], row[2]) for row in rows] == [
        ("| Hopper-v4", "reference", "25 x 200, own solver"),
        ("| Hopper-v4", "reference-fast", "25 x 200, fast solver"),
        ("| Swimmer-v4", "reference", "25 x 200, own solver"),
        ("| Swimmer-v4", "reference-solver-4-16", "25 x 200, solver 4 / 16"),
    ]
    for row, (finals, base) in zip(
        [rows[1], rows[3]],
        [(hopper["reference-fast"], hopper["reference"]),
         (swimmer["reference-solver-4-16"], swimmer["reference"])],
        strict=True,
    ):  # fmt: skip
        pairs = finals[:, None] - base[None, :]
        p = np.mean(pairs > 0) + 0.5 * np.mean(pairs == 0)
        assert row[4].startswith(f"{p:.2f} [")
        se = finals.std(ddof=1) / np.sqrt(5)
        assert row[3] == f"{finals.mean():,.1f} ± {se:,.1f}"
    assert rows[0][4] == "(baseline)"
    from pngail_jax.analysis.run_records import RecordError

    with pytest.raises(RecordError, match="has no arm 'table' to contrast with"):
        comparison_record.contrast_table(records, ["reference-fast"], "table")


def test_a_contrast_marker_is_rewritten_from_its_checked_records(recorded):
    from pngail_jax.jobs import comparison_record
    from pngail_jax.programs import record as record_program

    tmp_path, _, records = recorded
    (tmp_path / "contrast" / "docs").mkdir(parents=True)
    (tmp_path / "contrast" / "README.md").write_text("no tables\n")
    page = tmp_path / "contrast" / "docs" / "performance.md"
    marker = "<!-- record-contrast cmp cmp baseline=table arms=reference-fisher5 -->\n"
    page.write_text(marker + "| stale |\n<!-- /record-contrast -->\n")
    assert record_program.rewrite_docs(tmp_path / "contrast", records) == [page]
    record = comparison_record.check(records / "cmp")
    expected = comparison_record.contrast_table([record, record], ["reference-fisher5"], "table")
    assert page.read_text() == marker + expected + "<!-- /record-contrast -->\n"
    assert expected.count("| Pendulum-v1 | reference-fisher5 |") == 2
