"""The run's figures: evaluation curves (``curves.png``, like the paper's Fig. 2) and the
training diagnostics (``diagnostics.png``), from the grid's metrics; the tables and
statistics are ``pngail_jax.analysis.report``'s."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from pngail_jax.analysis import stats
from pngail_jax.analysis.report import normalize
from pngail_jax.config.presets import METHOD_NAMES, display_name
from pngail_jax.storage.integrity import atomic_path


def plot_curves(
    path: Path,
    cells,
    metrics,
    return_range,
    title: str,
    excluded=(),
    xlabel: str = "M environment steps per run",
) -> None:
    """Normalised evaluation return vs environment steps (``metrics["env_steps"]``; the
    offline family passes its gradient steps there, with its ``xlabel``): the mean over seeds
    with its 95% bootstrap interval per method (one panel per setting), like the paper's
    Fig. 2. Falls back to raw returns without a return range. Cells in ``excluded`` (diverged)
    are left out, as from the summary."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    returns = np.asarray(metrics["eval/return"], np.float64)
    values = normalize(returns, return_range) if return_range is not None else returns
    evaluated = ~np.isnan(returns).all(axis=0)
    settings = list(dict.fromkeys(cell.setting for cell in cells))
    methods = list(dict.fromkeys(cell.method for cell in cells))
    excluded = set(excluded)
    colors = dict(zip(methods, plt.get_cmap("tab10").colors * 2, strict=False))
    figure, axes = plt.subplots(
        1, len(settings), figsize=(7 * len(settings), 4.8), squeeze=False, sharey=True
    )
    for axis, setting in zip(axes[0], settings, strict=True):
        for method in methods:
            rows = [
                i
                for i, c in enumerate(cells)
                if c.method == method and c.setting == setting and i not in excluded
            ]
            if rows:
                steps = np.asarray(metrics["env_steps"])[rows[0], evaluated] / 1e6
                _plot_mean(axis, method, steps, values[rows][:, evaluated], colors[method])
        if return_range is not None:
            axis.axhline(1.0, color="grey", ls="--", lw=0.8)
            axis.axhline(0.0, color="grey", ls=":", lw=0.8)
        axis.set(
            xlabel=xlabel,
            ylabel="normalised return" if return_range is not None else "return",
            title=setting if len(settings) > 1 else None,
        )
        axis.grid(alpha=0.3)
    axes[0][-1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    figure.suptitle(f"{title}\nmean over seeds; shaded: 95% bootstrap interval of the mean")
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120, bbox_inches="tight")  # the legend is outside
    plt.close(figure)


def _plot_mean(axis, method: str, steps, curve, color) -> None:
    """``method``'s mean over seeds of ``curve`` float[seeds, T] against ``steps`` float[T],
    its 95% bootstrap interval shaded."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(curve, axis=0)
    low, high = np.array([stats.bootstrap_ci(column, np.mean) for column in curve.T]).T
    axis.plot(steps, mean, color=color, lw=1.8, ls=line_style(method), label=display_name(method))
    axis.fill_between(steps, low, high, color=color, alpha=0.12, lw=0)


# diagnostics.png's panels: (metric, title), read from the metrics every trainer records.
DIAGNOSTICS = (
    ("disc/acc_agent", "discriminator accuracy on agent rows"),
    ("disc/acc_demo", "discriminator accuracy on demonstration rows"),
    ("train/reward", "mean policy reward (the update's)"),
    ("rollout/mean_abs_action", "policy's mean |action|"),
    ("rollout/beyond_bounds", "share of action entries beyond the bounds"),
)


def plot_diagnostics(path: Path, cells, metrics, title: str, excluded=()) -> bool:
    """What the discriminator and the policy do, per iteration, against environment steps:
    one panel per ``DIAGNOSTICS`` metric the run recorded, the mean over seeds of each
    method (and setting) smoothed over a fiftieth of the run. A discriminator that
    saturates (accuracy on agent rows near 1, reward near 0) or a policy drifting past its
    action bounds shows here without reading ``metrics.csv``. Returns False, writing
    nothing, when the run recorded none of them."""
    panels = [(name, label) for name, label in DIAGNOSTICS if name in metrics]
    if not panels:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(dict.fromkeys((cell.method, cell.setting) for cell in cells))
    colors = dict(zip(groups, plt.get_cmap("tab10").colors * 4, strict=False))
    steps = np.asarray(metrics["env_steps"], np.float64)[0] / 1e6
    window = max(1, steps.size // 50)
    columns = min(len(panels), 3)
    rows_of_panels = -(-(len(panels) + 1) // columns)  # and a slot for the legend
    figure, axes = plt.subplots(
        rows_of_panels, columns, figsize=(4.6 * columns, 3.4 * rows_of_panels), squeeze=False
    )
    axes = axes.ravel()
    for axis, (name, label) in zip(axes, panels, strict=False):
        _diagnostic_panel(axis, name, label, cells, metrics, steps, window, colors, excluded)
    handles, labels = axes[0].get_legend_handles_labels()
    for axis in axes[len(panels) :]:
        axis.axis("off")
    axes[len(panels)].legend(handles, labels, loc="center", fontsize=9)
    smoothing = f"; moving average over {window} iterations" if window > 1 else ""
    figure.suptitle(f"{title}: diagnostics\nmean over seeds{smoothing}")
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=110, bbox_inches="tight")
    plt.close(figure)
    return True


def _diagnostic_panel(axis, name, label, cells, metrics, steps, window, colors, excluded):
    """One panel of ``plot_diagnostics``: metric ``name``, each method's (and setting's) mean
    over its seeds, smoothed over ``window`` iterations."""
    values = np.asarray(metrics[name], np.float64)
    several_settings = len({cell.setting for cell in cells}) > 1
    for method, setting in colors:
        rows = [
            i
            for i, c in enumerate(cells)
            if (c.method, c.setting) == (method, setting) and i not in set(excluded)
        ]
        if not rows:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            curve = _moving_average(np.nanmean(values[rows], axis=0), window)
        shown = display_name(method) + (f" ({setting})" if several_settings else "")
        axis.plot(
            steps, curve, color=colors[(method, setting)], lw=1.4, ls=line_style(method),
            label=shown,
        )  # fmt: skip
    axis.set(xlabel="M environment steps per run", title=label)
    if name == "train/reward" and np.nanmin(values, initial=0.0) < -1:
        # A logit reward (-z, down to about -7) beside rewards in [0, 1]: a scale that is
        # linear within +-1 and logarithmic beyond keeps both readable.
        axis.set_yscale("symlog", linthresh=1.0)
    axis.title.set_fontsize(9)
    axis.grid(alpha=0.3)


def _moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """The trailing mean of the last ``window`` values at each index (fewer at the start);
    NaN entries are skipped."""
    if window == 1:
        return values
    finite = np.isfinite(values)
    sums = np.cumsum(np.where(finite, values, 0.0))
    counts = np.cumsum(finite)
    sums[window:] = sums[window:] - sums[:-window].copy()
    counts[window:] = counts[window:] - counts[:-window].copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def line_style(method: str) -> str:
    """Dashed for PN-GAIL's ablations, dotted for methods beyond the paper's seven, so that
    curves stay apart where their colours and bands overlap."""
    if method.startswith("pngail-no-"):
        return "--"
    return "-" if method in METHOD_NAMES else ":"
