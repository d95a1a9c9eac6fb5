"""The vmappable split of a grid cell: labelled rows (D_c) and unlabelled rows (D_u) drawn
from a key, with their confidences (noised when the cell asks), as traced
arrays; ``cut_mixture``, a smaller mixture cut from a made set; ``successor_rows``, the rows
of the next states of each row's trajectory."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.demos.types import Demonstrations


@struct.dataclass
class Split:
    """One seed's D_c / D_u split of ``traj_size`` rows; leaves are [traj_size]."""

    indices: jax.Array  # int32, rows of the full set
    confidence: jax.Array  # float32, confidences the learner sees (after any noise)
    true_confidence: jax.Array  # float32, before noise (for MAE / RMSE)
    labelled: jax.Array  # bool, D_c


def make_split(
    key: jax.Array,
    confidence: jax.Array,
    traj_size: int,
    label_ratio: float | jax.Array,
    noise_std: float | jax.Array = 0.0,
    allowed: jax.Array | None = None,
) -> Split:
    """Draws ``traj_size`` rows; the first ``round(label_ratio * traj_size)`` are labelled.

    ``allowed`` (bool[N], None = every row) marks the rows whose confidence a learner may see
    (``Demonstrations.labelled``). The rows are drawn uniformly as without it; the drawn
    allowed rows then come first, each group in drawn order, and only they are labelled: the
    first ``min(round(label_ratio * traj_size), allowed rows drawn)``. With every row allowed
    the split is the one drawn without ``allowed``, bit for bit.

    Confidence noise ``clip(r + N(0, noise_std^2), 0, 1)`` as the paper's robustness test.
    ``traj_size`` is static (a shape); ``label_ratio``, ``noise_std`` and ``allowed`` are
    values, so a grid can vmap over them.
    """
    order_key, noise_key = jax.random.split(key)
    indices = jax.random.permutation(order_key, confidence.shape[0])[:traj_size]
    num_labelled = jnp.round(label_ratio * traj_size)
    if allowed is not None:
        chex.assert_shape(allowed, confidence.shape[:1])
        allowed_drawn = jnp.asarray(allowed, bool)[indices]
        # A stable sort keeps the drawn order within each group: all allowed = no reordering.
        indices = indices[jnp.argsort((~allowed_drawn).astype(jnp.int32), stable=True)]
        num_labelled = jnp.minimum(num_labelled, allowed_drawn.sum())
    true_confidence = confidence[indices]
    noise = noise_std * jax.random.normal(noise_key, true_confidence.shape)
    return Split(
        indices=indices.astype(jnp.int32),
        confidence=jnp.clip(true_confidence + noise, 0.0, 1.0),
        true_confidence=true_confidence,
        labelled=jnp.arange(traj_size) < num_labelled,
    )


def cut_mixture(
    source: Demonstrations, num_optimal: int, num_intermediate: int, name: str = "the mixture"
) -> Demonstrations:
    """The first ``num_optimal`` optimal and ``num_intermediate`` intermediate trajectories
    of a made set (optimal ones first, as ``make_demonstrations`` writes them), ids
    renumbered: a smaller mixture at another ratio without making again. ``name`` is for the
    error when the made set is too small."""
    made_optimal = source.metadata["num_optimal_trajectories"]
    made_total = len(source.metadata["trajectory_returns"])
    if num_optimal > made_optimal or num_intermediate > made_total - made_optimal:
        raise ValueError(
            f"{name}: needs {num_optimal} optimal + {num_intermediate} intermediate "
            f"trajectories, the made set has {made_optimal} + {made_total - made_optimal}"
        )
    kept = [*range(num_optimal), *range(made_optimal, made_optimal + num_intermediate)]
    rows = np.isin(source.trajectory_ids, kept)
    renumber = np.zeros(made_total, np.int64)
    renumber[kept] = np.arange(len(kept))
    returns = source.metadata["trajectory_returns"]
    return Demonstrations(
        observations=source.observations[rows],
        actions=source.actions[rows],
        confidence=source.confidence[rows],
        trajectory_ids=renumber[source.trajectory_ids[rows]],
        metadata={
            **source.metadata,
            "ratio": f"{num_optimal}:{num_intermediate}",
            "num_optimal_trajectories": num_optimal,
            "trajectory_returns": [returns[i] for i in kept],
            "source": f"{name}, cut from the made set",
        },
    )


def successor_rows(trajectory_ids: np.ndarray, rollback: int) -> np.ndarray:
    """int32[N, K]: per row, the rows of the next K states of its trajectory (k = 1..K; -1
    past its end), the rows in time order within each trajectory. ValueError when a
    trajectory's rows are not one contiguous run (then no row's successor is known)."""
    ids = np.asarray(trajectory_ids)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    if len(starts) != len(np.unique(ids)):
        raise ValueError(
            "ILID needs each trajectory's rows together and in time order; these "
            "trajectory ids come back after other trajectories' rows"
        )
    rows = np.arange(len(ids))[:, None] + np.arange(1, rollback + 1)[None, :]
    inside = rows < len(ids)
    same = np.zeros_like(inside)
    same[inside] = ids[rows[inside]] == np.broadcast_to(ids[:, None], rows.shape)[inside]
    return np.where(same, rows, -1).astype(np.int32)
