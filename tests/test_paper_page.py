"""The paper page's numbers: a series' statistics against NumPy, and Table 4's rows beside the
paper's, from made-up grid results (no training)."""

import numpy as np
import pytest

from pngail_jax.paper.page import series_statistics, table4_markdown
from pngail_jax.paper.plan import PAPER_TABLE4, PAPER_TABLE4_OPTIMAL, Figure, Series


def curves_of(rng, methods, seeds=4, evaluations=20):
    steps = np.arange(1, evaluations + 1) * 5000
    return {
        (method, "label_ratio=0.2,noise=0"): {
            "steps": steps,
            "normalized": rng.uniform(-0.2, 1.0, (seeds, evaluations)),
        }
        for method in methods
    }


def test_series_statistics_against_numpy():
    rng = np.random.default_rng(0)
    curves = curves_of(rng, ("gail", "pngail"))
    summary = {"methods": {"pngail": {"average_return_mean": -500.0, "average_return_se": 20.0}}}
    result = series_statistics(Series("PN-GAIL", "g", "pngail"), curves, summary)
    values = curves[("pngail", "label_ratio=0.2,noise=0")]["normalized"]
    late = values[:, -4:]  # the last 20% of 20 evaluations
    for name, per_seed in (
        ("final", values[:, -1]),
        ("average", values.mean(axis=1)),
        ("late", late.mean(axis=1)),
    ):
        entry = result[name]
        np.testing.assert_allclose(entry["mean"], per_seed.mean())
        np.testing.assert_allclose(entry["std"], per_seed.std(ddof=1))
        np.testing.assert_allclose(entry["se"], per_seed.std(ddof=1) / 2)  # sqrt(4 seeds)
        low, high = entry["ci95"]
        assert per_seed.min() <= low <= per_seed.mean() <= high <= per_seed.max()
        assert entry["seeds"] == 4
    assert result["average_return"] == [-500.0, 20.0]  # summary.json's, raw returns
    assert result["late_average_return"] == [None, None]  # not in that summary: None, not made up
    assert result["steps"] == list(range(5000, 100_001, 5000))


def test_a_series_that_matches_no_curve_or_several_is_refused():
    rng = np.random.default_rng(1)
    curves = curves_of(rng, ("gail",))
    with pytest.raises(ValueError, match="expected one curve"):
        series_statistics(Series("PN-GAIL", "g", "pngail"), curves, {"methods": {}})
    curves[("gail", "label_ratio=0.1,noise=0")] = curves[("gail", "label_ratio=0.2,noise=0")]
    with pytest.raises(ValueError, match="expected one curve"):
        series_statistics(Series("GAIL", "g", "gail"), curves, {"methods": {}})


def test_table4_puts_ours_beside_the_papers_for_each_task():
    figure = Figure(
        "table4",
        "Table 4",
        "average reward after convergence",
        {
            task: [Series("pngail", f"{task}-app", "pngail"), Series("gail", f"{task}-app", "gail")]
            for task in ("Pendulum-v1", "Ant-v4")
        },
    )
    results = {
        "Pendulum-v1": {
            "pngail": {"late_average_return": [-400.0, 12.5], "average_return": [-600.0, 30.0]},
            "gail": {"late_average_return": [-700.0, None], "average_return": [-800.0, 40.0]},
            "return_range": [-1200.96, -116.81],
        },
        "Ant-v4": {
            "pngail": {"late_average_return": [2500.0, 100.0], "average_return": [1500.0, 90.0]},
            "gail": {"late_average_return": [900.0, 50.0], "average_return": [700.0, 20.0]},
        },
    }
    lines = table4_markdown(figure, results)
    assert lines[0] == (
        "| method | Pendulum-v1: ours, last 20% of training | Pendulum-v1: ours, all of "
        "training | Pendulum-v1: paper (± std) | Ant-v4: ours, last 20% of training | Ant-v4: "
        "ours, all of training | Ant-v4: paper (± std) |"
    )
    (pendulum_paper, ant_paper) = PAPER_TABLE4["pngail"]
    assert lines[2] == (
        f"| PN-GAIL | -400.0 ± 12.5 | -600.0 ± 30.0 | {pendulum_paper[0]:.1f} ± "
        f"{pendulum_paper[1]:.1f} | 2500.0 ± 100.0 | 1500.0 ± 90.0 | {ant_paper[0]:.1f} ± "
        f"{ant_paper[1]:.1f} |"
    )
    assert lines[3] == (
        "| GAIL | -700.0 ± n/a | -800.0 ± 40.0 | not in the paper | 900.0 ± 50.0 | "
        "700.0 ± 20.0 | not in the paper |"
    )
    assert lines[4] == (
        f"| optimal policy | -116.8 | -116.8 | {PAPER_TABLE4_OPTIMAL[0]:.2f} | n/a | n/a | "
        f"{PAPER_TABLE4_OPTIMAL[1]:.2f} |"
    )
