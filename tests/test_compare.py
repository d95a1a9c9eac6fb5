"""Comparisons across runs and tasks (pngail_jax.analysis.compare, experiments.compare) against hand
computations of rliable's definitions."""

import json

import numpy as np
import pytest

from pngail_jax.analysis import compare
from pngail_jax.analysis.compare import Scores
from pngail_jax.analysis.report import write_metrics_csv
from pngail_jax.analysis.runs import sealed_part
from pngail_jax.grid import Cell
from pngail_jax.programs import compare as program
from pngail_jax.storage import outputs
from pngail_jax.storage.integrity import CONFIG_SEAL, seal
from pngail_jax.storage.outputs import prepare_output

A = {"t1": np.array([0.1, 0.5, 0.9]), "t2": np.array([0.2, 1.4])}
B = {"t1": np.array([0.0, 0.3, 0.6]), "t2": np.array([0.5, 0.7])}


def scores():
    return Scores({"a": A, "b": B})


def test_aggregates_equal_their_definitions_by_hand():
    s = scores()
    pooled = [0.1, 0.5, 0.9, 0.2, 1.4]
    by_hand = {
        "iqm": np.mean(sorted(pooled)[1:4]),  # 5 scores: int(1.25) = 1 cut from each end
        "mean": np.mean([np.mean(A["t1"]), np.mean(A["t2"])]),  # of the per-task means
        "median": np.median([np.mean(A["t1"]), np.mean(A["t2"])]),
        "optimality_gap": 1 - np.mean(np.minimum(pooled, 1.0)),  # 1.4 counts as 1
    }
    for name, expected in by_hand.items():
        value = compare.aggregate(s, "a", name, num_resamples=500)
        assert value["estimate"] == pytest.approx(expected), name
        assert value["ci95"] == pytest.approx(bootstrap_by_hand(name), rel=1e-12), name
        assert compare.aggregate(s, "a", name, num_resamples=500) == value  # seeded


def bootstrap_by_hand(name, num_resamples=500):
    """The 2.5th and 97.5th percentiles of aggregate ``name`` of a's scores over stratified
    resamples drawn as rliable's StratifiedBootstrap does: np.random.default_rng(0), each task
    in turn (t1, then t2) redrawing its own seeds with replacement, float[R, seeds] at a time."""
    rng = np.random.default_rng(0)
    t1 = A["t1"][rng.integers(0, 3, size=(num_resamples, 3))]
    t2 = A["t2"][rng.integers(0, 2, size=(num_resamples, 2))]
    pooled = np.sort(np.concatenate([t1, t2], axis=1), axis=1)
    task_means = np.stack([t1.mean(axis=1), t2.mean(axis=1)], axis=1)
    estimates = {
        "iqm": pooled[:, 1:4].mean(axis=1),  # 5 scores: 1 cut from each end
        "mean": task_means.mean(axis=1),
        "median": np.median(task_means, axis=1),  # of two task means: their mean
        "optimality_gap": 1 - np.minimum(pooled, 1.0).mean(axis=1),
    }[name]
    return np.percentile(estimates, [2.5, 97.5]).tolist()


def test_bootstrap_intervals_of_known_cases():
    """Every score equal: every resample is the same, each interval that value exactly. Two
    scores 0 and 1 on one task: a resample's mean is 0, 1/2 or 1 with chances 1/4, 1/2, 1/4,
    so of 2,000 resamples about 500 are 0 and 500 are 1, far more than the 50 below the 2.5th
    percentile or above the 97.5th: the interval is [0, 1]; the IQM of two scores (none cut)
    is their mean, the same; the optimality gap 1 - mean, [0, 1] too."""
    equal = Scores({"a": {"t1": np.full(3, 0.25), "t2": np.full(2, 0.25)}})
    for name, value in [("iqm", 0.25), ("mean", 0.25), ("median", 0.25), ("optimality_gap", 0.75)]:
        assert compare.aggregate(equal, "a", name) == {"estimate": value, "ci95": [value, value]}
    two = Scores({"a": {"t": np.array([0.0, 1.0])}})
    for name in ("iqm", "mean", "median", "optimality_gap"):
        assert compare.aggregate(two, "a", name) == {"estimate": 0.5, "ci95": [0.0, 1.0]}, name


def test_the_bootstrap_resamples_seeds_within_each_task():
    """Constant within each task: every stratified resample keeps 3 zeros and 2 ones, so the
    pooled mean (the optimality gap's) never moves; resampling all five would."""
    s = Scores({"a": {"t1": np.zeros(3), "t2": np.ones(2)}})
    assert compare.aggregate(s, "a", "optimality_gap")["ci95"] == pytest.approx([0.6, 0.6])
    assert compare.aggregate(s, "a", "mean")["ci95"] == pytest.approx([0.5, 0.5])


def test_probability_of_improvement_is_the_mean_over_tasks_of_pairs_won():
    value = compare.probability_of_improvement(scores(), "a", "b", num_resamples=500)
    t1 = (1 + 2 + 3) / 9  # 0.1 > 0; 0.5 > 0, 0.3; 0.9 > all three
    t2 = 2 / 4  # only 1.4 beats 0.5 and 0.7
    assert value["estimate"] == pytest.approx((t1 + t2) / 2)
    assert value["tasks"] == ["t1", "t2"]
    # The interval by hand: a's then b's seeds redrawn within t1, then within t2, each
    # resample's P(a > b) + P(a = b) / 2 counted pair by pair, averaged over the two tasks.
    rng = np.random.default_rng(0)
    per_task = []
    for task in ("t1", "t2"):
        a = A[task][rng.integers(0, A[task].size, size=(500, A[task].size))]
        b = B[task][rng.integers(0, B[task].size, size=(500, B[task].size))]
        pairs = a[:, :, None] - b[:, None, :]
        per_task.append(((pairs > 0) + 0.5 * (pairs == 0)).mean(axis=(1, 2)))
    by_hand = np.percentile(np.mean(per_task, axis=0), [2.5, 97.5])
    assert value["ci95"] == pytest.approx(by_hand.tolist(), rel=1e-12)
    ties = Scores({"a": {"t": np.array([1.0])}, "b": {"t": np.array([1.0])}})
    assert compare.probability_of_improvement(ties, "a", "b")["estimate"] == 0.5


def test_performance_profile_counts_scores_above_each_threshold():
    profile = compare.performance_profile(scores(), "a", np.array([0.0, 0.45, 2.0]))
    assert profile["fraction"] == pytest.approx([1.0, 3 / 5, 0.0])
    assert all(lo <= f <= hi for lo, f, hi in zip(*(profile[k] for k in ("low", "fraction",
               "high")), strict=True))  # fmt: skip


def test_only_tasks_every_method_ran_are_aggregated():
    s = Scores({"a": {**A, "t3": np.array([0.9])}, "b": B})
    result = compare.compare(s, "b", seed=0)
    assert result["tasks"] == ["t1", "t2"] and result["left_out"] == {"a": ["t3"]}
    assert result["aggregates"]["a"]["iqm"] == compare.aggregate(scores(), "a", "iqm")
    with pytest.raises(compare.CompareError, match="baseline 'c' is not among"):
        compare.compare(s, "c")


def test_methods_chosen_alone_widen_the_tasks_aggregated(tmp_path, capsys):
    """A method that ran one task only narrows the aggregates to that task; --methods leaves
    it out, and the others are aggregated over every task they ran (here, by the program)."""
    s = Scores({"a": A, "b": B, "c": {"t2": np.array([0.5, 0.6])}})
    assert compare.compare(s, "a")["tasks"] == ["t2"]
    assert compare.compare(s.only(["b", "a"]), "a")["tasks"] == ["t1", "t2"]
    assert s.only(["b", "a"]).methods == ["b", "a"]
    with pytest.raises(compare.CompareError, match="--methods: d not in the runs"):
        s.only(["a", "d"])
    with pytest.raises(compare.CompareError, match="--methods names no method"):
        s.only([])
    one = fake_run(tmp_path / "one", "t1", {"a": A["t1"], "b": B["t1"]})
    two = fake_run(tmp_path / "two", "t2", {"a": A["t2"], "b": B["t2"], "c": [0.5, 0.6]})
    out = program.main([str(one), str(two), "--methods", "a,b", "--out", str(tmp_path / "c")])
    assert json.loads((out / "compare.json").read_text())["tasks"] == ["t1", "t2"]
    with pytest.raises(SystemExit, match="--methods: x not in the runs"):
        program.main([str(one), "--methods", "a,x", "--out", str(tmp_path / "d")])
    capsys.readouterr()


def test_a_task_where_a_method_has_no_finite_score_is_left_out():
    s = Scores({"a": A, "b": {"t1": B["t1"], "t2": np.full(2, np.nan)}})
    result = compare.compare(s, "a")
    assert result["tasks"] == ["t1"] and result["left_out"] == {"a": ["t2"], "b": ["t2"]}
    empty = compare.performance_profile(Scores({"c": {"t": np.full(2, np.nan)}}), "c",
                                        np.array([0.5]))  # fmt: skip
    assert np.isnan(empty["fraction"][0])


def sealed_config(directory, document):
    """config.json and the seal a run writes with it; the return range the fake runs' metrics
    are written with (random -1000, optimal 0, under the older layouts' key "normalizer")
    unless ``document`` resolves another."""
    document = {"resolved": {"normalizer": [-1000.0, 0.0]}, **document}
    (directory / "config.json").write_text(json.dumps(document))
    seal(directory / CONFIG_SEAL, sealed_part(document))


def fake_run(directory, env, finals):
    """A sweep run's files: config.json (sealed), and metrics.csv with one evaluated
    iteration per method whose normalised returns are ``finals[method]`` (random -1000,
    optimal 0)."""
    prepare_output(directory, "sweep")
    sealed_config(directory, {"env": env})
    cells = [Cell(m, seed) for m, values in finals.items() for seed in range(len(values))]
    returns = np.array([[v * 1000 - 1000] for values in finals.values() for v in values])
    metrics = {name: np.zeros_like(returns) for name in ("disc/acc_agent", "disc/acc_demo",
               "train/reward", "trpo/kl", "train/episode_return")}  # fmt: skip
    metrics |= {"eval/return": returns, "env_steps": np.full_like(returns, 5000)}
    write_metrics_csv(directory / "metrics.csv", cells, metrics, (-1000.0, 0.0))
    return directory


def test_a_score_is_the_late_average_unless_the_final_evaluation_is_asked_for(tmp_path):
    """Ten evaluations a seed: the default score is the mean of the last 2 (the last 20% of
    training), --statistic final the last one; compare.md and compare.json say which."""
    prepare_output(tmp_path / "r", "sweep")
    sealed_config(tmp_path / "r", {"env": "t"})
    rng = np.random.default_rng(3)
    normalised = rng.uniform(0, 1, (4, 10))  # a seeds 0-1, b seeds 0-1
    cells = [Cell(m, seed) for m in ("a", "b") for seed in range(2)]
    returns = normalised * 1000 - 1000
    metrics = {name: np.zeros_like(returns) for name in ("disc/acc_agent", "disc/acc_demo",
               "train/reward", "trpo/kl", "train/episode_return")}  # fmt: skip
    steps = np.tile(np.arange(1, 11) * 5000, (4, 1))
    metrics |= {"eval/return": returns, "env_steps": steps}
    write_metrics_csv(tmp_path / "r" / "metrics.csv", cells, metrics, (-1000.0, 0.0))
    late = compare.load_scores([tmp_path / "r"])
    assert late.statistic == "late_average"
    np.testing.assert_allclose(late.values["b"]["t"], normalised[2:, -2:].mean(1), atol=1e-5)
    final = compare.load_scores([tmp_path / "r"], "final")
    np.testing.assert_allclose(final.values["b"]["t"], normalised[2:, -1], atol=1e-5)
    out = program.main([str(tmp_path / "r"), "--statistic", "final", "--out",
                        str(tmp_path / "c")])  # fmt: skip
    assert json.loads((out / "compare.json").read_text())["statistic"] == "final"
    assert "Score: Final normalised return (the last evaluation)" in (
        (out / "compare.md").read_text()
    )
    with pytest.raises(compare.CompareError, match="statistic 'best'"):
        compare.load_scores([tmp_path / "r"], "best")


def test_the_program_reads_runs_and_writes_its_page(tmp_path, capsys):
    one = fake_run(tmp_path / "one", "t1", {"a": A["t1"], "b": B["t1"]})
    two = fake_run(tmp_path / "two", "t2", {"a": A["t2"], "b": B["t2"]})
    out = program.main([str(one), str(two), "--baseline", "b", "--out", str(tmp_path / "c")])
    result = json.loads((out / "compare.json").read_text())
    expected = compare.compare(scores(), "b")
    assert result["aggregates"]["a"]["iqm"]["estimate"] == pytest.approx(
        expected["aggregates"]["a"]["iqm"]["estimate"]
    )
    assert result["probability_of_improvement"]["a"]["estimate"] == pytest.approx(
        expected["probability_of_improvement"]["a"]["estimate"]
    )
    for name in ("compare.md", "aggregates.png", "profiles.png", "improvement.png"):
        assert (out / name).stat().st_size > 0, name
    assert outputs.unaccounted(out, "compare") == []  # --overwrite knows all it wrote
    assert "P(method > b)" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="holds no sweep or offline run"):
        program.main([str(out), "--out", str(tmp_path / "d")])
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        program.main([str(one), "--out", str(one)])
    assert f"--out {one} is one of the runs: give another directory" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):  # not replaced without --overwrite
        program.main([str(one), str(two), "--out", str(out)])
    assert (
        f"--out {out} already holds a run of experiments.compare: pass --overwrite to replace it"
    ) in capsys.readouterr().err
    assert "Unfinished" not in (out / "compare.md").read_text() and not result["unfinished"]
    # A run still going (its summary.json says so) is compared, and named as unfinished.
    (two / "summary.json").write_text(
        json.dumps({"complete": False, "iterations_done": 1, "iterations": 500})
    )
    (one / "summary.json").write_text(json.dumps({"complete": True}))
    out = program.main([str(one), str(two), "--out", str(tmp_path / "e")])
    assert json.loads((out / "compare.json").read_text())["unfinished"] == {
        str(two): "1 of 500 iterations"
    }
    assert f"**Unfinished runs**, read up to their latest evaluation so far: {two} (1 of " in (
        (out / "compare.md").read_text()
    )
    (two / "summary.json").write_text(json.dumps({"complete": False, "iterations_done": 2}))
    assert compare.run_progress(two) == "unfinished"  # how far, when the summary says
    (two / "summary.json").write_text(json.dumps({"methods": {}}))  # before the key existed
    assert compare.run_progress(two) is None


def test_each_task_is_summarised_on_its_own_with_the_baselines_improvement():
    s = Scores({"a": {**A, "t3": np.array([0.9, 0.8])}, "b": B})
    table = compare.compare(s, "a", seed=0)["per_task"]
    assert list(table) == ["t1", "t2", "t3"]  # t3 too, though only a ran it
    row = table["t1"]["b"]
    assert row["seeds"] == 3 and row["mean"] == pytest.approx(0.3)
    assert row["se"] == pytest.approx(np.std([0.0, 0.3, 0.6], ddof=1) / np.sqrt(3))
    assert row["iqm"]["estimate"] == pytest.approx(0.3)  # 3 scores: int(0.75) = 0 cut
    assert row["baseline_improvement"]["estimate"] == pytest.approx(6 / 9)  # P(a > b) on t1
    low, high = row["baseline_improvement"]["ci95"]
    assert 0 <= low <= 6 / 9 <= high <= 1
    assert "baseline_improvement" not in table["t1"]["a"]  # the baseline itself
    assert list(table["t3"]) == ["a"]
    text = compare.markdown(compare.compare(s, "a", seed=0))
    assert "**t1**" in text and "| b | 3 | 0.30 ± 0.17 | 0.30 [" in text and "P(a > method)" in text
    one = compare.markdown(compare.compare(Scores({"a": {"t": np.array([0.5])}}), "a"))
    assert "| a | 1 | 0.50 (n = 1) | 0.50 [0.50, 0.50] | - |" in one


def long_fake_run(directory, env="t1", iterations=3, seed=0):
    """A sweep run of methods a and b x 2 seeds, ``iterations`` rows per cell, with the
    config.json fields that say which cells it holds."""
    fake_run(directory, env, {"a": [0.5, 0.6], "b": [0.2, 0.3]})
    config = {"env": env, "methods": ["a", "b"], "seeds": 2, "seed": seed,
              "iterations": iterations, "provenance": {"host": str(directory)}}  # fmt: skip
    sealed_config(directory, config)
    cells = [Cell(m, s) for m in ("a", "b") for s in range(2)]
    returns = np.tile(np.array([[-500.0], [-400.0], [-800.0], [-700.0]]), (1, iterations))
    metrics = {name: np.zeros_like(returns) for name in ("disc/acc_agent", "disc/acc_demo",
               "train/reward", "trpo/kl", "train/episode_return")}  # fmt: skip
    metrics |= {"eval/return": returns, "env_steps": np.full_like(returns, 5000)}
    write_metrics_csv(directory / "metrics.csv", cells, metrics, (-1000.0, 0.0))
    return directory


def refusal(runs, tmp_path, capsys) -> str:
    """The one line ``experiments.compare RUNS`` exits with (nothing written)."""
    out = tmp_path / "comparison"
    with pytest.raises(SystemExit) as stop:
        program.main([*map(str, runs), "--out", str(out)])
    assert not out.exists()
    message = str(stop.value.code) + capsys.readouterr().err
    assert "Traceback" not in message
    return message


def test_the_same_seeds_given_twice_are_refused_not_pooled(tmp_path, capsys):
    """Pooling a run with itself (or with a copy, or the same command run again) doubles n
    and shrinks the interval: refused, naming both."""
    import shutil

    run = long_fake_run(tmp_path / "run")
    assert "is given twice" in refusal([run, run], tmp_path, capsys)
    assert "is given twice" in refusal([run, tmp_path / "." / "run"], tmp_path, capsys)
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    config = json.loads((copy / "config.json").read_text())
    config["provenance"] = {"host": "another"}  # run again elsewhere: same seeds still
    (copy / "config.json").write_text(json.dumps(config))
    message = refusal([run, copy], tmp_path, capsys)
    assert "the same seeds of the same config" in message and str(run) in message
    # The same config run before and after the trainer's learner part (issue 74): its
    # resolved.trainer in two shapes, the same settings: still the same seeds.
    trpo, ppo = {"fisher": "gauss_newton"}, {"num_epochs": 10}
    for folder, trainer in (
        (run, {"learner": "trpo", "trpo": trpo, "ppo": ppo, "num_demos": 8}),
        (copy, {"learner": {"name": "trpo", "trpo": trpo, "ppo": ppo}, "num_demos": 8}),
    ):
        config = json.loads((folder / "config.json").read_text())
        sealed_config(folder, {**config, "resolved": {**config["resolved"], "trainer": trainer}})
    message = refusal([run, copy], tmp_path, capsys)
    assert "the same seeds of the same config" in message and str(copy) in message
    # Another base seed is other seeds: pooled.
    other = long_fake_run(tmp_path / "other", seed=1)
    scores = compare.load_scores([run, other])
    assert scores.values["a"]["t1"].size == 4


def test_a_damaged_metrics_file_is_named_in_one_line(tmp_path, capsys):
    run = long_fake_run(tmp_path / "run")
    path = run / "metrics.csv"
    good = path.read_text()
    lines = good.splitlines()
    for damaged, expected in (
        (good.replace("normalized_return", "normalised", 1), "no column"),  # a renamed column
        (good.replace(lines[1], "a,x," + lines[1].removeprefix("a,0,"), 1), "'x'"),  # a seed
        ("\x00\xff" * 50, "is damaged"),  # not text at all
    ):
        path.write_bytes(damaged.encode("latin-1") if "\xff" in damaged else damaged.encode())
        message = refusal([run], tmp_path, capsys)
        assert f"{path} is damaged" in message and expected in message, message


def test_a_metrics_file_cut_short_is_refused_not_read_as_final(tmp_path, capsys):
    run = long_fake_run(tmp_path / "run", iterations=3)
    path = run / "metrics.csv"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-1]))  # the last cell one row short
    assert "b seed 1 ends at iteration 2, other cells at 3" in refusal([run], tmp_path, capsys)
    path.write_text("".join(lines[:-3]))  # the last cell gone
    assert "it holds 1 of the 2 runs of b" in refusal([run], tmp_path, capsys)
    path.write_text("".join(lines))
    (run / "summary.json").write_text(
        json.dumps({"complete": False, "iterations_done": 5, "iterations": 10})
    )
    message = refusal([run], tmp_path, capsys)
    assert "ends at iteration 3, and summary.json says the run reached 5" in message
    (run / "summary.json").write_text(
        json.dumps({"complete": False, "iterations_done": 3, "iterations": 10})
    )
    assert compare.load_scores([run]).unfinished == {str(run): "3 of 10 iterations"}
