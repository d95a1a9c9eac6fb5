"""Statistics across seeds against hand computations and exact bootstrap distributions."""

import itertools
import math
import time
from collections import Counter

import numpy as np
import pytest
import scipy.stats

from pngail_jax.analysis.stats import (
    bootstrap_ci,
    iqm,
    probability_of_improvement,
    probability_of_improvement_ci,
    sample_std,
    seed_summary,
    split_half_agreement,
    standard_error,
)

NAN = float("nan")


# ---------------------------------------------------------------- IQM


def test_iqm_eight_values_drops_two_each_end():
    # int(0.25 * 8) = 2 dropped from each end: kept 3, 4, 5, 6.
    assert iqm([8, 1, 7, 2, 6, 3, 5, 4]) == (3 + 4 + 5 + 6) / 4 == 4.5


def test_iqm_five_values_drops_one_each_end_and_ignores_nan():
    # int(0.25 * 5) = 1: sorted 1, 3, 7, 10, 100 -> kept 3, 7, 10.
    assert iqm([10, 1, 7, 3, 100]) == pytest.approx((3 + 7 + 10) / 3, rel=1e-15)
    assert iqm([10, NAN, 1, 7, NAN, 3, 100]) == pytest.approx((3 + 7 + 10) / 3, rel=1e-15)


def test_iqm_ten_values_drops_two_each_end():
    # int(0.25 * 10) = 2: sorted -3, 1, 2, 7, 7, 9, 12, 40, 50, 100 -> kept 2, 7, 7, 9, 12, 40.
    values = [50, -3, 12, 7, 7, 1, 40, 2, 9, 100]
    assert iqm(values) == pytest.approx((2 + 7 + 7 + 9 + 12 + 40) / 6, rel=1e-15)


def test_iqm_small_counts_and_empty():
    assert iqm([2.0]) == 2.0
    assert iqm([1.0, 4.0, 10.0]) == 5.0  # int(0.75) = 0: the plain mean
    assert iqm([0.0, 1.0, 2.0, 100.0]) == 1.5  # int(1.0) = 1: kept 1, 2
    assert iqm([[1.0, 2.0], [3.0, 4.0]]) == 2.5  # flattened, like aggregate_iqm's axis=None
    assert math.isnan(iqm([]))
    assert math.isnan(iqm([NAN, np.inf, -np.inf]))
    assert isinstance(iqm([1, 2, 3]), float)


def test_iqm_along_axis_matches_trim_mean_row_by_row():
    rng = np.random.default_rng(3)
    for n in range(1, 13):
        rows = rng.normal(size=(7, n))
        expected = scipy.stats.trim_mean(rows, 0.25, axis=-1)
        np.testing.assert_allclose(iqm(rows, axis=-1), expected, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(iqm(rows.T, axis=0), expected, rtol=1e-13, atol=1e-15)
    # Each row is trimmed by its own finite count; a row with nothing finite is NaN.
    rows = np.array([[8, 1, 7, 2, 6, 3, 5, 4], [10, 1, 7, 3, 100, NAN, NAN, NAN], [NAN] * 8])
    result = iqm(rows, axis=-1)
    np.testing.assert_allclose(result[:2], [4.5, 20 / 3], rtol=1e-15)
    assert np.isnan(result[2])


# ---------------------------------------------------------------- spread


def test_sample_std_and_standard_error_by_hand():
    values = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]  # mean 5, squared deviations sum to 32
    std = math.sqrt(32 / 7)
    assert sample_std(values) == pytest.approx(std, rel=1e-15)
    assert standard_error(values) == pytest.approx(std / math.sqrt(8), rel=1e-15)
    # NaNs are dropped: [1, 3] has mean 2, squared deviations 2, ddof 1 -> variance 2.
    assert sample_std([1.0, NAN, 3.0]) == pytest.approx(math.sqrt(2), rel=1e-15)
    assert standard_error([1.0, NAN, 3.0]) == pytest.approx(1.0, rel=1e-15)


def test_spread_needs_two_values():
    for values in ([], [3.0], [3.0, NAN]):
        assert math.isnan(sample_std(values))
        assert math.isnan(standard_error(values))


# ---------------------------------------------------------------- bootstrap


def test_bootstrap_two_values_mean_is_full_range():
    # Resample means are 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4: the 2.5% and 97.5%
    # percentiles fall inside the atoms at 0 and 1.
    assert bootstrap_ci([0.0, 1.0], np.mean) == (0.0, 1.0)
    assert bootstrap_ci([0.0, 1.0], iqm) == (0.0, 1.0)  # n = 2 trims nothing


def _exact_quantile(values, statistic, q, margin=0.01):
    """The q-quantile of the exact bootstrap distribution (all n^n resamples), checked to lie
    at least ``margin`` of probability inside one atom, so that a large bootstrap hits it."""
    counts = Counter(statistic(np.array(r)) for r in itertools.product(values, repeat=len(values)))
    total, cumulative = sum(counts.values()), 0
    for atom in sorted(counts):
        below, cumulative = cumulative / total, cumulative + counts[atom]
        if cumulative / total > q:
            assert below < q - margin and cumulative / total > q + margin
            return atom
    raise AssertionError("unreachable")


def test_bootstrap_matches_exact_percentiles_of_enumerated_resamples():
    values = [0.0, 1.0, 2.0, 3.0]
    # Mean: sums of 4 draws from {0..3}; P(sum <= 1) = 5/256, P(sum <= 2) = 15/256, so the
    # 2.5% percentile is the mean 2/4 and by symmetry the 97.5% one is 10/4.
    assert _exact_quantile(values, np.mean, 0.025, margin=0.005) == 0.5
    assert _exact_quantile(values, np.mean, 0.975, margin=0.005) == 2.5
    assert bootstrap_ci(values, np.mean, num_resamples=20_000) == (0.5, 2.5)
    # IQM (mean of the middle two), 80% interval: P(IQM = 0) = 13/256, P(IQM <= 0.5) = 43/256.
    assert _exact_quantile(values, iqm, 0.10) == 0.5
    assert _exact_quantile(values, iqm, 0.90) == 2.5
    assert bootstrap_ci(values, iqm, confidence=0.8, num_resamples=20_000) == (0.5, 2.5)


def test_bootstrap_resamples_uniformly_with_replacement():
    values = np.array([0.0, 1.0, 2.0])
    seen = []

    def recording_mean(samples, axis=None):
        seen.append(samples)
        return np.mean(samples, axis=axis)

    bootstrap_ci(values, recording_mean, num_resamples=27_000, seed=5)
    (samples,) = seen
    assert samples.shape == (27_000, 3)
    # Each of the 27 ordered draws is equally likely: about 1000 each.
    codes = (samples[:, 0] * 9 + samples[:, 1] * 3 + samples[:, 2]).astype(int)
    frequencies = np.bincount(codes, minlength=27)
    assert np.all(np.abs(frequencies - 1000) < 5 * math.sqrt(1000))


def test_bootstrap_is_deterministic_in_seed():
    values = np.random.default_rng(0).normal(size=10)  # distinct values: many distinct IQMs
    assert bootstrap_ci(values, seed=1) == bootstrap_ci(values, seed=1)
    assert bootstrap_ci(values, seed=1) != bootstrap_ci(values, seed=2)


def test_bootstrap_contains_point_estimate():
    rng = np.random.default_rng(0)
    for n in (3, 5, 10, 30):
        values = rng.normal(size=n)
        for statistic in (iqm, np.mean, np.median):
            low, high = bootstrap_ci(values, statistic)
            assert low <= statistic(values) <= high
            assert low < high


def test_bootstrap_single_value_and_nothing_finite():
    assert bootstrap_ci([3.5]) == (3.5, 3.5)
    assert bootstrap_ci([NAN, 3.5, np.inf], np.mean) == (3.5, 3.5)
    low, high = bootstrap_ci([NAN, NAN])
    assert math.isnan(low) and math.isnan(high)


def test_bootstrap_stratified_keeps_stratum_counts():
    values, strata = [0.0, 0.0, 10.0, 10.0], [0, 0, 1, 1]
    # Two draws from each stratum: every resample is {0, 0, 10, 10}, mean and IQM exactly 5.
    assert bootstrap_ci(values, np.mean, strata=strata) == (5.0, 5.0)
    assert bootstrap_ci(values, iqm, strata=strata) == (5.0, 5.0)
    # Unstratified, resamples such as {0, 0, 0, 10} occur.
    low, high = bootstrap_ci(values, np.mean)
    assert low < 5.0 < high
    # Unequal strata (and a NaN dropped with its label) keep their sizes too.
    values = [1.0, 1.0, 1.0, NAN, 4.0, 4.0]
    seen = []

    def recording_sum(samples, axis=None):
        seen.append(samples)
        return np.sum(samples, axis=axis)

    assert bootstrap_ci(values, recording_sum, strata=[7, 7, 7, 2, 2, 2]) == (11.0, 11.0)
    assert np.all(np.sum(seen[0] == 1.0, axis=1) == 3)
    assert np.all(np.sum(seen[0] == 4.0, axis=1) == 2)


def test_bootstrap_statistic_without_axis_falls_back_to_rows():
    values = [0.1, 0.5, 0.3, 0.9, 0.7]
    vectorised = bootstrap_ci(values, np.median, seed=4)
    assert bootstrap_ci(values, lambda v: float(np.median(v)), seed=4) == vectorised
    low, high = bootstrap_ci(values, sample_std, seed=4)  # no axis argument
    assert 0.0 <= low < sample_std(values) < high


def test_bootstrap_rejects_bad_arguments():
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_ci([1.0, 2.0], confidence=1.0)
    with pytest.raises(ValueError, match="num_resamples"):
        bootstrap_ci([1.0, 2.0], num_resamples=0)
    with pytest.raises(ValueError, match="strata"):
        bootstrap_ci([1.0, 2.0], strata=[0])


def test_bootstrap_of_five_values_is_not_pathologically_slow():
    """A guard against a per-resample Python loop (2,000 resamples of a summary table's every
    cell), with a margin no shared machine misses: about 1 ms measured, 0.5 s allowed. The
    speed itself is measured by benchmarks/, not here."""
    values = [0.1, 0.5, 0.3, 0.9, 0.7]
    bootstrap_ci(values)
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        bootstrap_ci(values)
        best = min(best, time.perf_counter() - start)
    assert best < 0.5


# ---------------------------------------------------------------- probability of improvement


def test_probability_of_improvement_by_hand():
    # Pairs (1,2) x2 -> 0, (2,2) x2 -> 0.5 each, (3,2) x2 -> 1 each: (0+0+0.5+0.5+1+1) / 6.
    assert probability_of_improvement([1, 2, 3], [2, 2]) == 0.5
    # x = [1, 4], y = [0, 2, 4]: 1 beats 0 (1); 4 beats 0 and 2 (2) and ties 4 (0.5): 3.5 / 6.
    assert probability_of_improvement([1, 4, NAN], [0, 2, 4]) == 3.5 / 6
    assert probability_of_improvement([5, 6], [1, 2]) == 1.0
    assert probability_of_improvement([1, 2], [1, 2]) == 0.5
    assert math.isnan(probability_of_improvement([], [1.0]))
    assert math.isnan(probability_of_improvement([1.0], [NAN]))


def test_probability_of_improvement_is_mann_whitney_u_and_symmetric():
    rng = np.random.default_rng(1)
    for n, m in ((3, 4), (5, 5), (10, 7)):
        x = rng.integers(0, 5, size=n).astype(float)  # many ties
        y = rng.integers(0, 5, size=m).astype(float)
        p = probability_of_improvement(x, y)
        assert p + probability_of_improvement(y, x) == pytest.approx(1.0, abs=1e-15)
        u = scipy.stats.mannwhitneyu(x, y, alternative="greater").statistic
        assert p == pytest.approx(u / (n * m), abs=1e-15)


def test_probability_of_improvement_ci():
    x, y = [1.0, 2.0, 3.0, 4.0, 5.0], [0.5, 1.5, 2.5, 3.5]
    low, high = probability_of_improvement_ci(x, y, seed=3)
    assert low <= probability_of_improvement(x, y) <= high
    assert 0.0 <= low < high <= 1.0
    assert probability_of_improvement_ci(x, y, seed=3) == (low, high)
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=12), rng.normal(size=11)
    assert probability_of_improvement_ci(x, y, seed=3) == probability_of_improvement_ci(
        x, y, seed=3
    )
    assert probability_of_improvement_ci(x, y, seed=3) != probability_of_improvement_ci(
        x, y, seed=4
    )
    # Separated samples: every resample has P = 1; single values: the interval is the point.
    assert probability_of_improvement_ci([5, 6, 7], [1, 2]) == (1.0, 1.0)
    assert probability_of_improvement_ci([2.0], [2.0]) == (0.5, 0.5)
    low, high = probability_of_improvement_ci([], [1.0])
    assert math.isnan(low) and math.isnan(high)


def test_probability_of_improvement_ci_resamples_exactly():
    # x = [0, 1] against y = [0.5]: P is the fraction of 1s among the two draws of x, so it is
    # 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4 and the 95% interval is [0, 1].
    assert probability_of_improvement_ci([0.0, 1.0], [0.5]) == (0.0, 1.0)


# ---------------------------------------------------------------- summary


def test_seed_summary():
    values = [2.0, 4.0, 4.0, NAN, 4.0, 5.0, 5.0, 7.0, 9.0]
    summary = seed_summary(values)
    assert set(summary) == {"mean", "std", "se", "iqm", "ci95", "num_seeds"}
    assert summary["num_seeds"] == 8
    assert summary["mean"] == 5.0
    assert summary["std"] == pytest.approx(math.sqrt(32 / 7), rel=1e-15)
    assert summary["se"] == pytest.approx(math.sqrt(32 / 7) / math.sqrt(8), rel=1e-15)
    assert summary["iqm"] == (4 + 4 + 5 + 5) / 4
    assert summary["ci95"] == list(bootstrap_ci(values, iqm, seed=0))
    assert summary["ci95"][0] <= summary["iqm"] <= summary["ci95"][1]
    for key in ("mean", "std", "se", "iqm"):
        assert type(summary[key]) is float
    assert all(type(bound) is float for bound in summary["ci95"])
    assert type(summary["num_seeds"]) is int
    values = np.random.default_rng(0).normal(size=10)
    assert seed_summary(values, seed=1)["ci95"] != seed_summary(values, seed=0)["ci95"]


def test_seed_summary_undefined_parts_are_nan():
    one = seed_summary([3.0])
    assert (one["mean"], one["iqm"], one["ci95"], one["num_seeds"]) == (3.0, 3.0, [3.0, 3.0], 1)
    assert math.isnan(one["std"]) and math.isnan(one["se"])
    empty = seed_summary([NAN])
    assert empty["num_seeds"] == 0
    assert all(math.isnan(empty[key]) for key in ("mean", "std", "se", "iqm"))
    assert all(math.isnan(bound) for bound in empty["ci95"])


def test_split_half_agreement_on_known_cases():
    rng = np.random.default_rng(0)
    # Methods far apart and seeds that barely vary: every split agrees completely.
    separated = np.arange(4)[:, None] + 0.01 * rng.normal(size=(4, 10))
    agreement = split_half_agreement(separated, num_splits=200)
    assert agreement["kendall_tau"] == 1.0 and agreement["same_best"] == 1.0
    assert agreement["mean_abs_difference"] < 0.02 and agreement["half"] == 5
    # Methods that are one distribution: over many draws of such data, the halves agree as
    # by chance (tau about 0; the same best method in about 1 split of 6). One draw alone can
    # favour a method by luck, which the halves then share.
    draws = [
        split_half_agreement(rng.normal(size=(6, 10)), num_splits=100, seed=k) for k in range(40)
    ]
    assert abs(np.mean([d["kendall_tau"] for d in draws])) < 0.1
    assert np.mean([d["same_best"] for d in draws]) < 0.35
    # By hand, two seeds per half: scores [[0, 1, 2, 3], [3, 2, 1, 0]] have equal means in
    # half {0, 3} / {1, 2}, so a split either ties (tau 0) or reverses them (tau -1).
    tied = split_half_agreement(np.array([[0.0, 1, 2, 3], [3, 2, 1, 0]]), num_splits=300)
    assert -1 <= tied["kendall_tau"] <= 0
    with pytest.raises(ValueError, match="seeds >= 4"):
        split_half_agreement(np.zeros((3, 3)))
