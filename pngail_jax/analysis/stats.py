"""Statistics across seeds, as defined by rliable (Agarwal et al. 2021, "Deep RL at the edge
of the statistical precipice"): interquartile mean, stratified percentile bootstrap intervals
and the probability of improvement.

NumPy (and SciPy) on host arrays. Every function flattens its input and keeps only the finite
values (NaN and +-inf are dropped); a quantity that needs more values than remain is NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import overload

import numpy as np
from numpy.typing import ArrayLike

Statistic = Callable[..., float | np.ndarray]


def _scipy_stats():
    """scipy.stats, imported on first use: about a third of a program's import time, read
    only by the statistics after the last chunk (benchmarks/cold_start.py)."""
    import scipy.stats

    return scipy.stats


def _finite(values: ArrayLike) -> np.ndarray:
    """float64[k]: the finite entries of ``values``, flattened."""
    flat = np.asarray(values, np.float64).ravel()
    return flat[np.isfinite(flat)]


@overload
def iqm(values: ArrayLike, axis: None = None) -> float: ...
@overload
def iqm(values: ArrayLike, axis: int) -> np.ndarray: ...
def iqm(values: ArrayLike, axis: int | None = None) -> float | np.ndarray:
    """Interquartile mean: the mean of the finite values left after dropping ``int(0.25 k)``
    of the smallest and as many of the largest (k finite values; ``scipy.stats.trim_mean``'s
    rounding, rliable's ``aggregate_iqm``). NaN when no value is finite.

    ``axis=None`` pools every value into one float. With an ``axis`` the IQM is taken along it
    (each slice trimmed by its own finite count) and the result is an array without that axis.
    """
    if axis is None:
        finite = _finite(values)
        if finite.size == 0:
            return math.nan
        return float(_scipy_stats().trim_mean(finite, proportiontocut=0.25))
    x = np.moveaxis(np.asarray(values, np.float64), axis, -1)
    x = np.where(np.isfinite(x), x, np.nan)
    x = np.sort(x, axis=-1)  # NaN last
    count = np.sum(~np.isnan(x), axis=-1, keepdims=True)
    cut = count // 4  # == int(0.25 * count)
    position = np.arange(x.shape[-1])
    keep = (position >= cut) & (position < count - cut)
    kept = np.sum(keep, axis=-1)
    total = np.sum(np.where(keep, x, 0.0), axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(kept > 0, total / np.maximum(kept, 1), np.nan)


def sample_std(values: ArrayLike) -> float:
    """Sample standard deviation (ddof=1) of the finite values; NaN when fewer than 2."""
    finite = _finite(values)
    if finite.size < 2:
        return math.nan
    return float(np.std(finite, ddof=1))


def standard_error(values: ArrayLike) -> float:
    """Standard error of the mean, ``sample_std / sqrt(k)`` over the k finite values; NaN when
    k < 2."""
    finite = _finite(values)
    if finite.size < 2:
        return math.nan
    return float(np.std(finite, ddof=1) / math.sqrt(finite.size))


def _check_interval_args(confidence: float, num_resamples: int) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if num_resamples < 1:
        raise ValueError(f"num_resamples must be at least 1, got {num_resamples}")


def _percentile_interval(estimates: np.ndarray, confidence: float) -> tuple[float, float]:
    """The (1 - confidence)/2 and (1 + confidence)/2 quantiles of float[R] (linear
    interpolation, ``np.percentile``'s default, as arch's percentile interval uses)."""
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail])
    return float(low), float(high)


def _apply_rows(statistic: Statistic, samples: np.ndarray) -> np.ndarray:
    """float[R]: ``statistic`` of each row of float[R, n]; called once with ``axis=-1`` when
    it accepts that and returns one value per row, else row by row."""
    try:
        result = np.asarray(statistic(samples, axis=-1), np.float64)
    except TypeError:
        result = None
    if result is None or result.shape != samples.shape[:1]:
        result = np.array([statistic(row) for row in samples], np.float64)
    return result


def resample_indices(
    rng: np.random.Generator, strata: np.ndarray, num_resamples: int
) -> np.ndarray:
    """int[R, n]: bootstrap indices into n values, drawn with replacement within each stratum
    (a stratum of size m gets m draws from its own members); strata in sorted label order."""
    columns = []
    for label in np.unique(strata):
        members = np.flatnonzero(strata == label)
        draws = rng.integers(0, members.size, size=(num_resamples, members.size))
        columns.append(members[draws])
    return np.concatenate(columns, axis=1)


def bootstrap_ci(
    values: ArrayLike,
    statistic: Statistic = iqm,
    *,
    confidence: float = 0.95,
    num_resamples: int = 2000,
    seed: int = 0,
    strata: ArrayLike | None = None,
) -> tuple[float, float]:
    """Stratified percentile bootstrap interval of ``statistic`` (rliable's
    ``StratifiedBootstrap`` with the percentile method).

    Each of ``num_resamples`` resamples redraws the values with replacement independently
    within each stratum, keeping every stratum's size; ``statistic`` is taken on the pooled
    resample and the interval is the ``(1 - confidence) / 2`` and ``(1 + confidence) / 2``
    quantiles of those estimates.

    Args: values float[n] (flattened); statistic maps float[n] to a number, and is called once
    on float[R, n] with ``axis=-1`` when it accepts that; strata int[n] labels (default: one
    stratum, i.e. plain iid resampling). Non-finite values and their labels are dropped first.
    Deterministic in ``seed`` (``np.random.default_rng``). Returns ``(nan, nan)`` when no value
    is finite; a single value v gives ``(v, v)`` for any location statistic; NaN estimates make
    the bound NaN.
    """
    _check_interval_args(confidence, num_resamples)
    x = np.asarray(values, np.float64).ravel()
    if strata is None:
        labels = np.zeros(x.shape, np.int64)
    else:
        labels = np.asarray(strata).ravel()
        if labels.shape != x.shape:
            raise ValueError(f"strata has {labels.size} labels for {x.size} values")
    finite = np.isfinite(x)
    x, labels = x[finite], labels[finite]
    if x.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    samples = x[resample_indices(rng, labels, num_resamples)]
    return _percentile_interval(_apply_rows(statistic, samples), confidence)


def improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """float[...]: P(X > Y) + P(X = Y) / 2 of float[..., n] against float[..., m], by the
    Mann-Whitney identity U = (rank sum of x in the pooled sample) - n (n + 1) / 2 with
    midranks for ties."""
    n, m = x.shape[-1], y.shape[-1]
    ranks = _scipy_stats().rankdata(np.concatenate([x, y], axis=-1), axis=-1)
    u = np.sum(ranks[..., :n], axis=-1) - n * (n + 1) / 2.0
    return u / (n * m)


def probability_of_improvement(x: ArrayLike, y: ArrayLike) -> float:
    """P(X > Y) + P(X = Y) / 2 over all pairs of finite values of ``x`` and ``y``: the
    Mann-Whitney U of x divided by n m (rliable's ``probability_of_improvement`` on one task).
    NaN when either side has no finite value."""
    xf, yf = _finite(x), _finite(y)
    if xf.size == 0 or yf.size == 0:
        return math.nan
    greater = np.sum(xf[:, None] > yf[None, :])
    equal = np.sum(xf[:, None] == yf[None, :])
    return float((greater + 0.5 * equal) / (xf.size * yf.size))


def probability_of_improvement_ci(
    x: ArrayLike,
    y: ArrayLike,
    *,
    confidence: float = 0.95,
    num_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``probability_of_improvement(x, y)``, resampling the
    finite values of x and of y independently, each keeping its size (rliable's
    ``StratifiedIndependentBootstrap``). ``(nan, nan)`` when either side is empty;
    deterministic in ``seed``."""
    _check_interval_args(confidence, num_resamples)
    xf, yf = _finite(x), _finite(y)
    if xf.size == 0 or yf.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    x_samples = xf[rng.integers(0, xf.size, size=(num_resamples, xf.size))]
    y_samples = yf[rng.integers(0, yf.size, size=(num_resamples, yf.size))]
    return _percentile_interval(improvement(x_samples, y_samples), confidence)


def seed_summary(values: ArrayLike, *, seed: int = 0) -> dict:
    """Summary of one quantity across seeds (values flattened, non-finite ones dropped).

    Returns ``{"mean", "std" (ddof 1), "se", "iqm", "ci95": [low, high] (95% bootstrap
    interval of the IQM, 2000 resamples), "num_seeds" (int, the finite count)}``; floats are
    Python floats and NaN where undefined (no value; std and se with fewer than 2).
    """
    finite = _finite(values)
    low, high = bootstrap_ci(finite, iqm, seed=seed)
    return {
        "mean": float(np.mean(finite)) if finite.size else math.nan,
        "std": sample_std(finite),
        "se": standard_error(finite),
        "iqm": iqm(finite),
        "ci95": [low, high],
        "num_seeds": int(finite.size),
    }


def split_half_agreement(scores: ArrayLike, *, num_splits: int = 1000, seed: int = 0) -> dict:
    """How well two re-runs agree when each has half the seeds: ``scores`` float[M, S] (M
    methods, S seeds, S >= 4, finite) split at random into two halves of S // 2 seeds, many
    times (``num_splits``, a fixed ``seed``); per split, each half's per-method means.

    Returns the means over splits of ``kendall_tau`` (the two halves' method orderings; 1:
    the same order), ``same_best`` (the share of splits whose halves put the same method
    first) and ``mean_abs_difference`` (|half A's mean - half B's| averaged over methods: how
    far a method's figure moves between re-runs), with ``num_splits`` and ``half``."""
    scores = np.asarray(scores, np.float64)
    if scores.ndim != 2 or scores.shape[1] < 4 or not np.isfinite(scores).all():
        raise ValueError(f"scores must be finite float[methods, seeds >= 4], got {scores.shape}")
    rng = np.random.default_rng(seed)
    num_seeds = scores.shape[1]
    half = num_seeds // 2
    taus, same_best, differences = [], [], []
    for _ in range(num_splits):
        order = rng.permutation(num_seeds)
        first = scores[:, order[:half]].mean(axis=1)
        second = scores[:, order[half : 2 * half]].mean(axis=1)
        tau = _scipy_stats().kendalltau(first, second).statistic
        taus.append(0.0 if np.isnan(tau) else tau)
        same_best.append(np.argmax(first) == np.argmax(second))
        differences.append(np.mean(np.abs(first - second)))
    return {
        "kendall_tau": float(np.mean(taus)),
        "same_best": float(np.mean(same_best)),
        "mean_abs_difference": float(np.mean(differences)),
        "num_splits": num_splits,
        "half": half,
    }
