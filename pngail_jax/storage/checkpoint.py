"""Self-describing policy checkpoints: parameters (orbax) plus the JSON needed to rebuild them.

``load_policy(path)`` needs neither the training code nor the environment: the directory holds
``policy.json`` (architecture, action bounds, observation normaliser flag, per-seed final
evaluation returns), ``policy_params/`` (orbax), with a leading seed axis on every array, and
``digests.json`` (every file's SHA-256, written last: ``load_policy`` refuses a damaged or
incomplete directory and names the file at fault).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp

from pngail_jax.networks import GaussianPolicy
from pngail_jax.rl.on_policy import ObservationNormalizer
from pngail_jax.storage.integrity import (
    MANIFEST_NAME,
    IntegrityError,
    read_json,
    verify_manifest,
    write_json,
    write_manifest,
)

# 2 added digests.json; version 1 directories (no digests) still load, unverified.
POLICY_FORMAT_VERSION = 2
READABLE_POLICY_FORMATS = (1, 2)


def save_policies(
    directory: str | Path,
    *,
    env_name: str,
    observation_size: int,
    action_low: np.ndarray,
    action_high: np.ndarray,
    hidden_sizes: tuple[int, ...],
    policy_params,
    normalizer,
    normalize_observations: bool,
    final_eval_returns: np.ndarray,
    extra: dict | None = None,
    write_metadata: bool = True,
) -> Path:
    """Saves stacked per-seed policies (every leaf has a leading seed axis) to ``directory``.

    In a multi-process run every process calls it (orbax synchronises them) and one, with
    ``write_metadata``, writes ``policy.json`` and ``digests.json``. A non-finite final return
    (a diverged seed) is stored as null and never chosen as the best seed."""
    directory = Path(directory).absolute()
    directory.mkdir(parents=True, exist_ok=True)
    (directory / MANIFEST_NAME).unlink(missing_ok=True)  # incomplete until written again
    normalizer_fields = ("count", "mean", "sum_squares")
    arrays = {
        "policy_params": policy_params,
        "normalizer": {name: getattr(normalizer, name) for name in normalizer_fields},
    }
    checkpointer = ocp.StandardCheckpointer()
    checkpointer.save(directory / "policy_params", jax.device_get(arrays), force=True)
    checkpointer.wait_until_finished()
    if not write_metadata:
        return directory
    metadata = {
        "format_version": POLICY_FORMAT_VERSION,
        "env": env_name,
        "observation_size": int(observation_size),
        "action_size": len(action_low),
        "action_low": [float(x) for x in action_low],
        "action_high": [float(x) for x in action_high],
        "hidden_sizes": list(hidden_sizes),
        "normalize_observations": bool(normalize_observations),
        "final_eval_returns": [float(x) if np.isfinite(x) else None for x in final_eval_returns],
        **(extra or {}),
    }
    write_json(directory / "policy.json", metadata)
    write_manifest(directory)
    return directory


def save_trpo_policies(
    directory, env, config, trpo_state, eval_returns, extra=None, write_metadata=True
) -> Path:
    """Saves the stacked per-seed policies of a ``TRPOState`` (``config``: its ``RolloutConfig``)
    with what ``load_policy`` needs (``write_metadata``: see ``save_policies``)."""
    return save_policies(
        directory,
        env_name=env.name,
        observation_size=env.observation_size,
        action_low=env.action_low,
        action_high=env.action_high,
        hidden_sizes=config.hidden_sizes,
        policy_params=trpo_state.policy_params,
        normalizer=trpo_state.normalizer,
        normalize_observations=config.normalize_observations,
        final_eval_returns=eval_returns,
        extra=extra,
        write_metadata=write_metadata,
    )


def load_policies(directory: str | Path) -> tuple[dict, ObservationNormalizer, np.ndarray]:
    """The stacked per-seed policies ``save_policies`` wrote in ``directory`` (its files
    checked against their digests), as they were given to it: the policy parameters and
    the observation normaliser, every leaf with a leading seed axis (``float32[seeds,
    ...]``), and the final evaluation returns float[seeds] (NaN where a seed diverged)."""
    directory = Path(directory).absolute()
    metadata = _policy_metadata(directory, verbose=False)
    arrays = ocp.StandardCheckpointer().restore(directory / "policy_params")
    returns = [np.nan if r is None else r for r in metadata["final_eval_returns"]]
    normalizer = ObservationNormalizer(**arrays["normalizer"])
    return arrays["policy_params"], normalizer, np.asarray(returns, np.float64)


# The keys load_policy reads from policy.json.
POLICY_KEYS = (
    "observation_size",
    "action_size",
    "action_low",
    "action_high",
    "hidden_sizes",
    "normalize_observations",
    "final_eval_returns",
)


def load_policy(
    directory: str | Path, seed: int | None = None, verbose: bool = True
) -> Callable[[np.ndarray], np.ndarray]:
    """Loads a saved policy as ``policy(obs) -> action`` (deterministic mean action).

    ``obs``: float32[obs_size] or a batch float32[..., obs_size]; the saved observation
    normaliser is applied. Actions are in the environment's own units, clipped to its bounds.
    With several seeds, ``seed=None`` picks the best final evaluation return and says which.
    """
    directory = Path(directory).absolute()
    metadata = _policy_metadata(directory, verbose)
    seed = _pick_seed(metadata, seed, directory / "policy.json", verbose)
    arrays = ocp.StandardCheckpointer().restore(directory / "policy_params")
    arrays = jax.tree.map(lambda x: jnp.asarray(x[seed]), arrays)
    policy = GaussianPolicy(metadata["action_size"], tuple(metadata["hidden_sizes"]))
    low = jnp.asarray(metadata["action_low"], jnp.float32)
    high = jnp.asarray(metadata["action_high"], jnp.float32)
    normalizer = ObservationNormalizer(**arrays["normalizer"])
    observation_size = metadata["observation_size"]

    @jax.jit
    def act(obs):
        if metadata["normalize_observations"]:
            obs = normalizer(obs)
        mean, _ = policy.apply(arrays["policy_params"], obs)
        return jnp.clip(mean, low, high)

    def policy_fn(obs) -> np.ndarray:
        obs = np.asarray(obs, np.float32)
        if obs.shape[-1:] != (observation_size,):
            raise ValueError(
                f"observation must have shape (..., {observation_size}), got {obs.shape}"
            )
        if not np.isfinite(obs).all():  # a NaN in would be a NaN action out, silently
            raise ValueError("observation contains NaN or infinite values")
        return np.asarray(act(obs))

    policy_fn.seed = seed
    policy_fn.metadata = metadata
    return policy_fn


def _policy_metadata(directory: Path, verbose: bool) -> dict:
    """policy.json of a saved policy, its files checked against digests.json (whenever that
    is there), and the keys ``load_policy`` reads present."""
    metadata_path = directory / "policy.json"
    if not metadata_path.exists():
        raise FileNotFoundError(f"no policy.json in {directory}: not a saved policy directory")
    metadata = read_json(metadata_path, "policy description")
    version = metadata.get("format_version") if isinstance(metadata, dict) else None
    if version not in READABLE_POLICY_FORMATS:
        raise IntegrityError(f"{metadata_path}: unsupported format_version {version!r}")
    # digests.json, where it is, is always checked: a format_version edited back to 1 does
    # not switch the check off.
    if version >= 2 or (directory / "digests.json").exists():
        verify_manifest(directory)
    elif verbose:
        print(f"load_policy: {directory} was saved without digests (format 1): not verified")
    missing = sorted(set(POLICY_KEYS) - set(metadata))
    if missing:
        raise IntegrityError(f"{metadata_path}: damaged policy description, lacks {missing}")
    return metadata


def _pick_seed(metadata: dict, seed, metadata_path: Path, verbose: bool) -> int:
    """``seed`` checked, or the seed with the best final evaluation return (said so)."""
    returns = [np.nan if r is None else r for r in metadata["final_eval_returns"]]
    if seed is None:
        if not np.isfinite(returns).any():
            raise ValueError(f"{metadata_path}: no seed has a finite final return; pass seed=")
        seed = int(np.nanargmax(returns))
        if verbose and len(returns) > 1:
            print(
                f"load_policy: seed {seed} of {len(returns)} (best final evaluation return "
                f"{returns[seed]:.1f})"
            )
    elif isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ValueError(f"seed must be an integer in [0, {len(returns)}), got {seed!r}")
    elif not 0 <= seed < len(returns):
        raise ValueError(f"seed must be in [0, {len(returns)}), got {seed}")
    return int(seed)


def is_key(x) -> bool:
    """Whether ``x`` (an array or ShapeDtypeStruct) holds typed PRNG keys."""
    return hasattr(x, "dtype") and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def save_tree(directory: str | Path, tree) -> None:
    """Saves any pytree of arrays (typed PRNG keys included, as their key data) with orbax.

    Leaves are stored flat by position (``leaf_00000``, ...); empty leaves (MJX states hold
    some, and orbax refuses them) are not stored. ``restore_tree`` rebuilds the structure from
    a template of the same structure, e.g. ``jax.eval_shape`` of the init function.
    """
    leaves = jax.tree.leaves(jax.device_get(tree))
    arrays = {
        f"leaf_{i:05d}": np.asarray(jax.random.key_data(x) if is_key(x) else x)
        for i, x in enumerate(leaves)
    }
    arrays = {name: value for name, value in arrays.items() if value.size > 0}
    checkpointer = ocp.StandardCheckpointer()
    checkpointer.save(Path(directory).absolute(), arrays, force=True)
    checkpointer.wait_until_finished()


def restore_tree(directory: str | Path, template):
    """The pytree ``save_tree`` wrote, as host arrays shaped like ``template``'s leaves."""
    arrays = ocp.StandardCheckpointer().restore(Path(directory).absolute())
    leaves, treedef = jax.tree.flatten(template)
    expected = sum(math.prod(like.shape) > 0 for like in leaves)
    if len(arrays) != expected:
        # A state of another shape: most often a checkpoint of another version whose
        # training state had other fields, which no leaf-by-leaf message would say.
        raise ValueError(
            f"{directory}: holds {len(arrays)} arrays where this version's state has "
            f"{expected}: a checkpoint of another pngail-jax version or another state, which "
            "this version cannot resume (CHANGELOG.md lists the changes to the training state)"
        )
    restored = []
    for i, like in enumerate(leaves):
        name = f"leaf_{i:05d}"
        if name not in arrays:
            if math.prod(like.shape) == 0:
                restored.append(np.zeros(like.shape, like.dtype))
                continue
            raise ValueError(f"{directory}: no array {name}; not a checkpoint of this state")
        value = np.asarray(arrays[name])
        if is_key(like):
            value = jax.random.wrap_key_data(value)  # the default implementation
        elif value.shape != like.shape or value.dtype != like.dtype:
            raise ValueError(
                f"{directory}: leaf {i} is {value.dtype}{value.shape}, expected "
                f"{like.dtype}{like.shape}"
            )
        restored.append(value)
    return jax.tree.unflatten(treedef, restored)
