"""Summaries, CSV and plot from synthetic grid metrics (two settings, one diverged cell)."""

import csv
import json

import numpy as np
import pytest
from conftest import as_sweep_run

from pngail_jax.analysis import plots, report, stats
from pngail_jax.grid import make_cells, nonfinite_cells

RETURN_RANGE = (-1200.0, -200.0)


def synthetic_metrics(cells, num_iterations=6, eval_every=3):
    rng = np.random.default_rng(0)
    grid = len(cells)
    evaluated = (np.arange(num_iterations) + 1) % eval_every == 0
    returns = rng.uniform(-1200, -200, (grid, num_iterations))
    metrics = {
        "env_steps": np.tile(np.arange(1, num_iterations + 1) * 100, (grid, 1)),
        "eval/return": np.where(evaluated, returns, np.nan),
        "disc/loss": rng.uniform(1, 2, (grid, num_iterations)),
        "disc/acc_agent": rng.uniform(size=(grid, num_iterations)),
        "disc/acc_demo": rng.uniform(size=(grid, num_iterations)),
        "train/reward": rng.uniform(size=(grid, num_iterations)),
        "trpo/kl": rng.uniform(0, 0.01, (grid, num_iterations)),
        "train/episode_return": returns,
        "confidence/mae": rng.uniform(0, 0.2, grid),
    }
    return metrics


def test_summary_groups_by_method_and_setting_and_drops_diverged_cells(tmp_path):
    cells = make_cells(["gail", "pngail"], 3, label_ratios=(0.1, 0.2))
    metrics = synthetic_metrics(cells)
    metrics["disc/loss"][4, 2] = np.nan  # pngail seed 1 at label ratio 0.1 diverges
    diverged = nonfinite_cells(metrics, eval_every=3)
    assert diverged.tolist() == [4]
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0, excluded=diverged)
    assert list(summary["methods"]) == [
        "gail [label_ratio=0.1,noise=0]",
        "pngail [label_ratio=0.1,noise=0]",
        "gail [label_ratio=0.2,noise=0]",
        "pngail [label_ratio=0.2,noise=0]",
    ]
    final = metrics["eval/return"][:, -1]
    row = summary["methods"]["pngail [label_ratio=0.1,noise=0]"]
    assert row["num_seeds"] == 2
    np.testing.assert_allclose(row["final_return_mean"], final[[3, 5]].mean())
    np.testing.assert_allclose(row["final_return_std"], final[[3, 5]].std(ddof=1))
    np.testing.assert_allclose(row["final_return_se"], final[[3, 5]].std(ddof=1) / np.sqrt(2))
    normalized = (final[[3, 5]] + 1200) / 1000
    np.testing.assert_allclose(row["final_normalized_return_mean"], normalized.mean())
    assert row["final_normalized_return_iqm"] == stats.iqm(normalized)
    assert row["final_normalized_return_ci95"] == list(stats.bootstrap_ci(normalized))
    average = np.nanmean(metrics["eval/return"][[3, 5]], axis=1)  # every evaluation of a seed
    np.testing.assert_allclose(row["average_return_mean"], average.mean())
    per_seed = row["per_seed"]
    assert [s["seed"] for s in per_seed] == [0, 1, 2] and np.isnan(per_seed[1]["final_return"])
    assert per_seed[2]["final_return"] == final[5]
    # each seed's own classifier error, for telling a bad seed's labels from its training
    assert per_seed[2]["confidence_mae"] == metrics["confidence/mae"][5]
    assert "confidence_rmse" not in per_seed[2]  # not measured, not made up
    improvement = summary["probability_of_improvement"]
    assert list(improvement) == ["gail [label_ratio=0.1,noise=0]", "gail [label_ratio=0.2,noise=0]"]
    assert improvement["gail [label_ratio=0.1,noise=0]"]["estimate"] == (
        stats.probability_of_improvement(final[[3, 5]], final[[0, 1, 2]])
    )
    text = json.dumps(report.json_safe(summary), allow_nan=False)  # summary.json: no bare NaN
    assert (
        json.loads(text)["methods"]["pngail [label_ratio=0.1,noise=0]"]["per_seed"][1][
            "final_return"
        ]
        is None
    )

    report.write_metrics_csv(tmp_path / "m.csv", cells, metrics, RETURN_RANGE, (1.5, 3.25))
    with open(tmp_path / "m.csv") as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == len(cells) * 6
    # one column per grid axis; each iteration carries its chunk's end (2 chunks of 3)
    assert [(r["label_ratio"], r["noise"]) for r in rows[::6]] == [("0.1", "0")] * 6 + [
        ("0.2", "0")
    ] * 6
    assert [r["wall_seconds"] for r in rows[:6]] == ["1.5"] * 3 + ["3.2"] * 3
    assert rows[0]["eval_return"] == ""  # not an evaluation iteration
    np.testing.assert_allclose(  # both written to 6 significant digits
        float(rows[2]["normalized_return"]),
        (float(rows[2]["eval_return"]) + 1200) / 1000,
        rtol=1e-4,
    )

    plots.plot_curves(tmp_path / "curves.png", cells, metrics, RETURN_RANGE, "test")
    assert (tmp_path / "curves.png").stat().st_size > 10_000
    markdown = report.summary_markdown(summary, cells, metrics, "test")
    # per method and setting, PN-GAIL's improvement over each baseline, and per seed
    assert markdown.count("\n| ") == (1 + 4) + (1 + 2) + (1 + 12)
    assert "| GAIL [label_ratio=0.1,noise=0] | 3 |" in markdown
    assert markdown.count("| reads none |") == 2  # GAIL reads no confidences
    assert "mean ± standard error (s.e." in markdown


def test_one_seed_gets_no_interval_and_raw_returns_no_normalised_column():
    cells = make_cells(["gail", "pngail"], 1)
    metrics = synthetic_metrics(cells)
    summary = report.summarize(cells, metrics, None, 1000.0, 2.0)
    markdown = report.summary_markdown(summary, cells, metrics, "t")
    assert "normalised" not in markdown.split("\n")[2]  # the header: raw returns only
    assert "(n = 1)" in markdown and "[" not in markdown.split("\n")[4]  # no interval
    assert "give --optimal-return for normalised ones" in markdown


def test_no_return_range_gives_nan_normalised_returns():
    assert np.isnan(report.normalize([-300.0], None)).all()
    np.testing.assert_allclose(report.normalize([-700.0], RETURN_RANGE), [0.5])


def test_a_method_whose_seeds_all_diverge_is_null_with_a_reason(tmp_path):
    cells = make_cells(["gail", "pngail"], 2)
    metrics = synthetic_metrics(cells)
    metrics["disc/loss"][2:, 4] = np.inf  # both pngail seeds
    metrics["eval/return"][2:, 5] = np.nan
    summary = report.summarize(
        cells, metrics, RETURN_RANGE, 1.0, 1.0, excluded=nonfinite_cells(metrics, 3)
    )
    report.write_summary(tmp_path, summary, "# summary\n")

    def no_bare_constants(name):
        raise AssertionError(f"summary.json holds a bare {name}")

    written = json.loads((tmp_path / "summary.json").read_text(), parse_constant=no_bare_constants)
    row = written["methods"]["pngail"]
    assert row["num_seeds"] == 0 and row["diverged_seeds"] == [0, 1]
    assert row["final_return_mean"] is None and "diverged" in row["note"]
    assert (
        written["methods"]["gail"]["diverged_seeds"] == []
        and "note" not in written["methods"]["gail"]
    )
    assert "every seed diverged" in written["null_means"]
    assert written["probability_of_improvement"]["gail"]["estimate"] is None


def test_late_average_is_the_mean_of_the_last_fifth_of_the_evaluations():
    """The headline (the last 20% of training: ceil of a fifth of the evaluations, 6 of 30,
    10 of 50, 1 of 5, 3 of 11) beside the average over all of training, each under its own
    name; the probability of improvement is the headline's, the final evaluation's beside it."""
    assert [report.late_evaluations(n) for n in (30, 50, 5, 11, 1)] == [6, 10, 1, 3, 1]
    cells = make_cells(["gail", "pngail"], 2)
    metrics = synthetic_metrics(cells, num_iterations=300, eval_every=10)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    assert summary["headline"] == {"statistic": "late_average", "late_share": 0.2}
    evaluations = metrics["eval/return"][:, 9::10]  # iterations 10, 20, ..., 300
    assert evaluations.shape == (4, 30) and np.isfinite(evaluations).all()
    for index, seed in enumerate(summary["methods"]["pngail"]["per_seed"]):
        row = 2 + index
        np.testing.assert_allclose(seed["late_average_return"], evaluations[row, -6:].mean())
        np.testing.assert_allclose(seed["average_return"], evaluations[row].mean())
        np.testing.assert_allclose(
            seed["late_average_normalized_return"], (evaluations[row, -6:].mean() + 1200) / 1000
        )
    np.testing.assert_allclose(report.late_average(evaluations), evaluations[:, -6:].mean(1))
    late, final = evaluations[:, -6:].mean(1), evaluations[:, -1]
    assert summary["probability_of_improvement"]["gail"]["estimate"] == (
        stats.probability_of_improvement(late[2:], late[:2])
    )
    assert summary["probability_of_improvement_final"]["gail"]["estimate"] == (
        stats.probability_of_improvement(final[2:], final[:2])
    )
    markdown = report.summary_markdown(summary, cells, metrics, "t")
    header = markdown.splitlines()[2]
    assert header.startswith("| method | seeds | last 20% of training, normalised return: IQM")
    assert "all of training, normalised return" in header
    assert "mean return over the last 20% of training > a baseline seed's" in markdown
    assert "| over | P(PN-GAIL > baseline) | 95% CI | final evaluation: P | 95% CI |" in markdown


def test_seeds_puts_a_methods_seeds_side_by_side_with_their_training(tmp_path, capsys):
    from pngail_jax.programs import seeds

    cells = make_cells(["gail", "pngail"], 3)
    metrics = synthetic_metrics(cells, num_iterations=20, eval_every=5)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    report.write_metrics_csv(tmp_path / "metrics.csv", cells, metrics, RETURN_RANGE)
    report.write_summary(tmp_path / ".", summary, "")
    as_sweep_run(tmp_path, RETURN_RANGE)
    table = seeds.main([str(tmp_path), "--method", "pngail", "--share", "0.25"])
    lates = [row["late_average_normalized_return"] for row in table]
    assert lates == sorted(lates, reverse=True) and len(table) == 3  # best seed first
    row = next(r for r in table if r["seed"] == 1)  # cell 4: pngail seed 1
    np.testing.assert_allclose(row["kl_late"], metrics["trpo/kl"][4, -5:].mean(), rtol=1e-5)
    np.testing.assert_allclose(
        row["disc_acc_agent_all"], metrics["disc/acc_agent"][4].mean(), rtol=1e-4
    )
    np.testing.assert_allclose(row["confidence_mae"], metrics["confidence/mae"][4], rtol=1e-6)
    assert "| seed | last 20% of training | final |" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="no rows of method 'bc'"):
        seeds.main([str(tmp_path), "--method", "bc"])
    # Two settings: each one's numbers from its own rows and summary entry, exactly.
    cells = make_cells(["pngail"], 2, noise_stds=(0.0, 0.1))
    metrics = synthetic_metrics(cells, num_iterations=10, eval_every=5)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    report.write_metrics_csv(tmp_path / "metrics.csv", cells, metrics, RETURN_RANGE)
    report.write_summary(tmp_path / ".", summary, "")
    _, table = seeds.seed_table(tmp_path, "pngail", "label_ratio=0.2,noise=0")
    finals = {row["seed"]: row["final_normalized_return"] for row in table}
    expected = report.normalize(metrics["eval/return"][:2, -1], RETURN_RANGE)
    np.testing.assert_allclose([finals[0], finals[1]], expected)
    with pytest.raises(SystemExit, match="several settings, pick one with --setting"):
        seeds.seed_table(tmp_path, "pngail")


def test_read_evaluations_keeps_the_evaluated_rows_per_group(tmp_path):
    """The one metrics.csv reader of the paper page and compare_settings: rows between
    evaluations (empty or NaN) are skipped; groups by the named columns; seeds in order; a
    seed missing an evaluation (diverged) gets NaN there."""
    path = tmp_path / "metrics.csv"
    path.write_text(
        "method,setting,seed,iteration,env_steps,eval_return,normalized_return\n"
        "gail,s,1,1,10,,\n"
        "gail,s,1,2,20,-5.0,0.5\n"
        "gail,s,0,2,20,-7.0,0.25\n"
        "pngail,s,0,2,20,-1.0,\n"
        "gail,s,0,4,40,-3.0,0.75\n"
        "gail,s,1,4,40,-2.0,0.8\n"
        "gail,s,1,3,30,nan,\n"
    )
    curves = report.read_evaluations(
        path, "normalized_return", evaluated_by="eval_return", group_by=("method", "setting")
    )
    assert set(curves) == {("gail", "s"), ("pngail", "s")}
    steps, values = curves[("gail", "s")]
    assert steps.tolist() == [20, 40] and values.tolist() == [[0.25, 0.75], [0.5, 0.8]]
    steps, values = curves[("pngail", "s")]
    assert steps.tolist() == [20] and np.isnan(values).all()  # evaluated, no return range
    with path.open("a") as file:  # seed 0 evaluated at 6, seed 1 not (diverged): NaN there
        file.write("gail,s,0,6,60,-1.0,0.9\n")
    steps, values = report.read_evaluations(path, "eval_return", group_by=("method",))[("gail",)]
    assert steps.tolist() == [20, 40, 60]
    np.testing.assert_array_equal(values, [[-7.0, -3.0, -1.0], [-5.0, -2.0, np.nan]])
    path.write_text(
        "seed,iteration,env_steps,eval/return\n0,1,10,nan\n0,2,20,-5\n1,2,20,-6\n1,1,10,nan\n"
    )
    ((steps, values),) = report.read_evaluations(path, "eval/return").values()
    assert steps.tolist() == [20] and values.tolist() == [[-5.0], [-6.0]]


def test_a_baseline_turns_the_improvement_around(tmp_path):
    """--baseline gail: P(each other method's seed > a GAIL seed's), per setting, and the
    table says so."""
    cells = make_cells(["gail", "wgail", "pngail"], 3)
    metrics = synthetic_metrics(cells)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0, baseline="gail")
    final = metrics["eval/return"][:, -1]
    improvement = summary["probability_of_improvement"]
    assert list(improvement) == ["wgail", "pngail"] and summary["improvement"] == {"over": "gail"}
    assert improvement["wgail"]["estimate"] == stats.probability_of_improvement(
        final[3:6], final[0:3]
    )
    text = report.summary_markdown(summary, cells, metrics, "t")
    assert "| method | P(method > GAIL) | 95% CI |" in text
    default = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    assert default["improvement"] == {"of": "pngail"} and list(
        default["probability_of_improvement"]
    ) == ["gail", "wgail"]


def test_moving_average_against_numpy():
    """The trailing mean of the last w values (fewer at the start), NaN entries skipped."""
    values = np.random.default_rng(1).normal(size=23)
    values[[4, 5, 17]] = np.nan
    for window in (1, 3, 7):
        expected = [np.nanmean(values[max(0, i - window + 1) : i + 1]) for i in range(23)]
        expected = np.where(np.isnan(values) & (window == 1), np.nan, expected)
        np.testing.assert_allclose(plots._moving_average(values, window), expected, 1e-12)
    np.testing.assert_array_equal(plots._moving_average(np.full(4, np.nan), 2), np.nan)


def test_diagnostics_plot_needs_the_metrics_it_draws(tmp_path):
    from pngail_jax.grid import make_cells

    cells = make_cells(["gail", "pngail"], num_seeds=2)
    metrics = {"env_steps": np.tile(np.arange(1, 61) * 5000, (4, 1))}
    assert not plots.plot_diagnostics(tmp_path / "d.png", cells, metrics, "test")
    assert not (tmp_path / "d.png").exists()
    rng = np.random.default_rng(0)
    metrics.update({name: rng.uniform(size=(4, 60)) for name, _ in plots.DIAGNOSTICS[:3]})
    assert plots.plot_diagnostics(tmp_path / "d.png", cells, metrics, "test", excluded=[1])
    assert (tmp_path / "d.png").stat().st_size > 10_000


def test_one_seed_a_method_gives_a_single_comparison_not_an_interval():
    """P(PN-GAIL > GAIL) from one seed each is 0 or 1 with a degenerate interval: the table
    says n = 1, as its other columns do."""
    cells = make_cells(["gail", "pngail"], 1)
    metrics = synthetic_metrics(cells)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    assert summary["probability_of_improvement"]["gail"]["seeds"] == [1, 1]
    row = next(
        line
        for line in report.summary_markdown(summary, cells, metrics, "t").splitlines()
        if line.startswith("| GAIL |") and "no interval" in line
    )
    estimate = summary["probability_of_improvement"]["gail"]["estimate"]
    assert row.startswith(f"| GAIL | {estimate:.2f} (n = 1) | no interval |")


def test_summary_tables_name_methods_as_the_paper_does():
    cells = make_cells(["pngail-no-bsc", "2iwil"], 2, label_ratios=(0.1, 0.2))
    metrics = synthetic_metrics(cells)
    summary = report.summarize(cells, metrics, RETURN_RANGE, 1000.0, 2.0)
    text = report.summary_markdown(summary, cells, metrics, "t")
    assert "pngail-no-bsc" in next(iter(summary["methods"]))  # the JSON keeps the ids
    rows = {line.split(" | ")[0] for line in text.splitlines() if line.startswith("| ")}
    assert rows == {
        "| method",
        *(f"| {name} [label_ratio={ratio},noise=0]" for name in ("PN-GAIL\\BSC", "2IWIL")
          for ratio in (0.1, 0.2)),
    }  # fmt: skip
