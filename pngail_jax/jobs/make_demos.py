"""Imperfect demonstrations made from scratch: an optimal and an intermediate TRPO policy, mixed.

    from pngail_jax.jobs.make_demos import MakeDemosConfig, make_demonstrations

    path = make_demonstrations(MakeDemosConfig(env="Pendulum-v1"), "demos/pendulum")

1. ``train_candidates``: TRPO on the true reward (``seeds`` in one program), keeping every
   evaluated checkpoint (``checkpoints/iter_XXXX/``, loadable with ``pngail_jax.load_policy``)
   and the learner's whole state after every block (``training/``, the last two kept).
2. ``pick_policies``: the optimal policy is the best-evaluated checkpoint; the intermediate
   policy is the earlier checkpoint whose evaluated normalised return is closest to
   ``intermediate_target`` (0.45: the authors' Pendulum set has intermediate confidences of
   0.37-0.50), not the optimal policy plus noise. The random (uniform actions) and optimal
   returns are measured on fresh episodes (the paper's Table 3).
3. ``roll_out_mixture``: ``num_trajectories`` deterministic (mean-action) episodes at the
   optimal:intermediate ``ratio`` (1:4 as the paper's Pendulum set), each trajectory labelled
   with its return normalised between random and optimal (clipped to [0, 1]); actions clipped
   to the bounds, as the environment applies them; the random and optimal returns in the metadata.

``config.json`` (sealed) is written first and ``demos.npz`` last and atomically (a temporary
sibling renamed onto it), so its presence means the making finished; then ``training/`` goes.
A making cut short resumes (``resume=True``, or ``python -m experiments.make_demos --resume
DIR``) from its last block, to the demonstrations of an uninterrupted one.
``python -m experiments.make_demos`` is this with flags.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax.config import settings as env_settings
from pngail_jax.config import validation
from pngail_jax.config.learner import LearnerConfig
from pngail_jax.config.training import check_training
from pngail_jax.demos.generate import normalized_return, random_policy_return, rollout_episodes
from pngail_jax.demos.npz import save_npz
from pngail_jax.demos.types import Demonstrations
from pngail_jax.jobs.errors import RunError, refusals
from pngail_jax.jobs.make_demos_run import (
    DEMOS_FILE,
    PROGRAM,
    TRAINING,
    begin_making,
    kept_snapshots,
    making_document,
)
from pngail_jax.jobs.train_seeds import train_seeds
from pngail_jax.rl import PolicyTrainer
from pngail_jax.rl.learners import learner_hyperparams, make_learner
from pngail_jax.storage.checkpoint import save_trpo_policies
from pngail_jax.storage.integrity import atomic_path, atomic_write_text
from pngail_jax.storage.outputs import Claim, claimed


@dataclasses.dataclass(frozen=True)
class MakeDemosConfig:
    """What to make: TRPO's budget, the mixture and its measurement. ``settings`` None: the
    task's row of ``pngail_jax.config.settings`` with an evaluation every 10 iterations (the
    intermediate policy is picked among the evaluated checkpoints: finer than the table's)."""

    env: str = "Pendulum-v1"
    iterations: int = 150  # policy iterations (TRPO or PPO)
    seeds: int = 3  # TRPO seeds; the best is optimal
    seed: int = 0  # base PRNG seed
    ratio: str = "1:4"  # optimal:intermediate trajectories
    num_trajectories: int = 5  # trajectories in the mixture
    intermediate_target: float = 0.45  # normalised return the intermediate policy is picked near
    measure_episodes: int = 64  # episodes for the random and optimal returns
    settings: env_settings.RunSettings | None = None
    # The policy learner that trains the candidates (config.learner.LearnerConfig; a name
    # alone is that learner at its defaults).
    learner: LearnerConfig = LearnerConfig()

    def __post_init__(self):
        # env, settings (the table's, evaluated every 10 iterations), the budget and the
        # learner, as every training job's
        check_training(self, eval_every=10)
        for name in ("num_trajectories", "measure_episodes"):
            validation.integer(name, getattr(self, name), 1)
        self.ratio_parts  # noqa: B018  (checks the ratio)
        if not 0 < self.intermediate_target < 1:
            validation.fail(
                "intermediate_target", f"must be in (0, 1), got {self.intermediate_target}"
            )

    @property
    def ratio_parts(self) -> tuple[float, float]:
        try:
            optimal, intermediate = (float(x) for x in self.ratio.split(":"))
        except ValueError:
            optimal = intermediate = None
        if optimal is None:
            validation.fail("ratio", f"must look like 1:4, got {self.ratio!r}")
        total = optimal + intermediate
        if not (optimal >= 0 and intermediate >= 0 and 0 < total < math.inf):  # no NaN
            validation.fail(
                "ratio",
                f"parts must be finite, non-negative and not both 0, got {self.ratio!r}",
            )
        return optimal, intermediate

    @property
    def num_optimal(self) -> int:
        optimal, intermediate = self.ratio_parts
        return round(self.num_trajectories * optimal / (optimal + intermediate))

    @property
    def rollout_config(self):
        return self.settings.rollout_config(self.iterations)


class Checkpoint(NamedTuple):
    """One evaluated policy of the TRPO run: where it came from and its evaluated return."""

    iteration: int
    seed: int
    policy_params: Any
    normalizer: Any  # the policy's observation statistics (rl.ObservationNormalizer)
    eval_return: float


@dataclasses.dataclass(frozen=True)
class Picked:
    """The mixture's two policies and the returns that normalise confidences."""

    optimal: Checkpoint
    intermediate: Checkpoint
    random_return: float
    optimal_return: float
    intermediate_return: float


def make_demonstrations(
    config: MakeDemosConfig,
    out,
    *,
    overwrite: bool = False,
    wait: bool = False,
    resume: bool = False,
    continue_cut: bool = False,
    command: Sequence[str] | None = None,
) -> Path:
    """Makes ``config``'s demonstrations into ``out`` (``config.json``, ``demos.npz``,
    ``normalizer.json``, ``checkpoints/``) and returns the path of ``demos.npz``. ``out`` must
    be new, empty or, with ``overwrite``, an earlier making's (``pngail_jax.storage.outputs``);
    ``resume``: continue the making cut short in ``out``, begun with the same config (and
    ``command``, the program's flags, which config.json keeps for its ``--resume``);
    ``continue_cut`` (with ``overwrite``: a job's own folder): continue a cut making of
    ``config`` there, else replace what is there. Refusals
    raise ``RunError`` with one line; a second process on the same ``out`` is refused, or with
    ``wait`` waits for the first to end. A stop asked for by a signal handler ends at the next
    block's checkpoint."""
    out = Path(out)
    with refusals(), claimed(out, PROGRAM, overwrite=overwrite, wait=wait, resume=resume) as claim:
        return make_claimed(config, claim, command, continue_cut)


def make_claimed(config: MakeDemosConfig, claim: Claim, command=None, continue_cut=False) -> Path:
    """``make_demonstrations`` into a directory already claimed (``claim``; resumed where it
    says so, or with ``continue_cut`` where it holds this config's making cut short)."""
    out = claim.directory
    try:
        # Sized for Warp's widest batch: the seeds' training, or the episodes rolled at once.
        widest = max(config.seeds, config.measure_episodes, config.num_trajectories)
        env = env_settings.make_env(config.env, config.settings, cells=widest)
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise RunError(f"environment: {error}") from None
    begin_making(claim, making_document(config, command), continue_cut)  # old run kept so far
    start = time.perf_counter()
    snapshots = train_candidates(config, env, out)
    print("2/3 measuring random and optimal returns", flush=True)
    episodes = CheckpointEpisodes(env, config.rollout_config)
    picked = pick_policies(config, env, snapshots, episodes)
    demos = roll_out_mixture(config, env, picked, episodes)
    path = write_demonstrations(out, demos, {k: demos.metadata[k] for k in RETURN_RANGE_KEYS})
    shutil.rmtree(out / TRAINING, ignore_errors=True)  # finished: nothing left to resume
    print(policies_table(picked))
    _, first_rows = np.unique(demos.trajectory_ids, return_index=True)
    confidences = [float(c) for c in demos.confidence[np.sort(first_rows)]]
    print(
        f"\n{demos.num_rows} rows in {len(confidences)} trajectories, confidences "
        f"{[round(c, 2) for c in confidences]}; wrote {path} "
        f"in {time.perf_counter() - start:.0f} s"
    )
    return path


def train_candidates(config: MakeDemosConfig, env, out: Path) -> list[Checkpoint]:
    """TRPO on the true reward, every evaluated checkpoint of every seed kept (in memory and
    under ``out/checkpoints/iter_XXXX/``), the whole state after every block under
    ``out/training/``, from which a making cut short continues (the checkpoints of the
    blocks before the one it restores read back from ``out/checkpoints/``)."""
    rollout = config.rollout_config
    learner = make_learner(config.learner, rollout, env)
    trainer = PolicyTrainer(rollout, env, learner=learner)
    hyperparams = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (config.seeds, *x.shape)),
        learner_hyperparams(config.learner.name),
    )
    snapshots: list[Checkpoint] = []

    def keep(iteration, state, metrics):
        if not snapshots:  # resumed after this block: the earlier ones are kept on disk
            kept = kept_snapshots(out, rollout.eval_every, iteration)
            snapshots.extend(Checkpoint(*fields) for fields in kept)
        returns = metrics["eval/return"][:, -1]
        save_trpo_policies(
            out / "checkpoints" / f"iter_{iteration:04d}", env, rollout, state, returns
        )
        for seed in range(config.seeds):
            pick = jax.tree.map(lambda x, s=seed: x[s], (state.policy_params, state.normalizer))
            snapshots.append(Checkpoint(iteration, seed, *pick, float(returns[seed])))

    print(
        f"1/3 training {config.learner.name.upper()} on {config.env} ({config.seeds} seeds x "
        f"{config.iterations} iterations; {env_settings.describe(config.settings)})",
        flush=True,
    )
    train_key = _keys(config)[0]
    keys = jax.random.split(train_key, config.seeds)
    train_seeds(trainer, hyperparams, keys, on_block=keep, checkpoints=out / TRAINING)
    return snapshots


def _keys(config: MakeDemosConfig):
    """(training, measuring, rolling out): the three uses of the base seed."""
    return jax.random.split(jax.random.key(config.seed), 3)


class CheckpointEpisodes:
    """Deterministic episodes of any checkpoint, one compiled program for all of them (the
    parameters are arguments, not constants)."""

    def __init__(self, env, rollout):
        policy = PolicyTrainer(rollout, env).learner.policy

        @jax.jit
        def episodes(params, normalizer, keys):
            def act(obs, key):
                return policy.apply(params, normalizer(obs))[0]

            return rollout_episodes(env, act, keys)

        self._episodes = episodes

    def __call__(self, snapshot: Checkpoint, key, num_episodes: int):
        keys = jax.random.split(key, num_episodes)
        return self._episodes(snapshot.policy_params, snapshot.normalizer, keys)


def pick_policies(
    config: MakeDemosConfig, env, snapshots: list[Checkpoint], episodes: CheckpointEpisodes
) -> Picked:
    """The best checkpoint (optimal), the earlier one nearest ``intermediate_target``, and
    the random, optimal and intermediate returns measured on fresh episodes."""
    random_key, optimal_key, intermediate_key = jax.random.split(_keys(config)[1], 3)
    random_return = random_policy_return(env, random_key, config.measure_episodes)
    best = max(snapshots, key=lambda snapshot: snapshot.eval_return)
    optimal_return = float(episodes(best, optimal_key, config.measure_episodes).returns.mean())
    if not optimal_return > random_return:
        print(
            f"WARNING: the best policy ({optimal_return:.1f}) does not beat the random one "
            f"({random_return:.1f}); confidences will be meaningless. Train longer "
            "(--iterations).",
            flush=True,
        )
    # An earlier checkpoint; if the best came first, any other one (and say so).
    candidates = [s for s in snapshots if s.iteration < best.iteration]
    if not candidates:
        print(
            "WARNING: the best checkpoint is the first one; the intermediate policy is "
            "picked among the later ones",
            flush=True,
        )
        candidates = [s for s in snapshots if s is not best] or snapshots
    intermediate = min(
        candidates,
        key=lambda s: abs(
            normalized_return(s.eval_return, random_return, optimal_return)
            - config.intermediate_target
        ),
    )
    intermediate_return = float(
        episodes(intermediate, intermediate_key, config.measure_episodes).returns.mean()
    )
    return Picked(best, intermediate, random_return, optimal_return, intermediate_return)


def roll_out_mixture(
    config: MakeDemosConfig, env, picked: Picked, episodes: CheckpointEpisodes
) -> Demonstrations:
    """``num_trajectories`` deterministic episodes of the two policies at ``ratio`` (the
    optimal ones first), each labelled with its clipped normalised return."""
    num_optimal = config.num_optimal
    print(
        f"3/3 rolling out {num_optimal} optimal + "
        f"{config.num_trajectories - num_optimal} intermediate trajectories",
        flush=True,
    )
    optimal_key, intermediate_key = jax.random.split(_keys(config)[2])
    sources = [
        (picked.optimal, optimal_key, num_optimal),
        (picked.intermediate, intermediate_key, config.num_trajectories - num_optimal),
    ]
    parts = [episodes(snapshot, key, count) for snapshot, key, count in sources if count > 0]
    rows, trajectory_returns = _labelled_rows(parts, env, picked)
    metadata = {
        "env": config.env,
        "action_scale": 1.0,
        "random_return": picked.random_return,
        "optimal_return": picked.optimal_return,
        "intermediate_return": picked.intermediate_return,
        "optimal_checkpoint": {"iteration": picked.optimal.iteration, "seed": picked.optimal.seed},
        "intermediate_checkpoint": {
            "iteration": picked.intermediate.iteration,
            "seed": picked.intermediate.seed,
        },
        "ratio": config.ratio,
        # The optimal policy's trajectories come first (ids 0 .. num_optimal - 1).
        "num_optimal_trajectories": num_optimal,
        "trajectory_returns": trajectory_returns,
        "optimal_beats_random": picked.optimal_return > picked.random_return,
        "source": f"experiments.make_demos (deterministic {config.learner.name.upper()} policies)",
        "learner": config.learner.name,
        "env_options": config.settings.env_options,
    }
    demos = Demonstrations(**{k: np.concatenate(v) for k, v in rows.items()}, metadata=metadata)
    demos.check_env(env)
    return demos


def _labelled_rows(parts, env, picked: Picked):
    """Rows of the valid steps of each episode, labelled with the episode's confidence."""
    rows = {"observations": [], "actions": [], "confidence": [], "trajectory_ids": []}
    trajectory_returns = []
    for episodes in parts:
        episodes = jax.device_get(episodes)
        for index in range(len(episodes.returns)):
            valid = episodes.valid[index]
            confidence = float(
                np.clip(
                    normalized_return(
                        episodes.returns[index], picked.random_return, picked.optimal_return
                    ),
                    0.0,
                    1.0,
                )
            )
            trajectory_returns.append(float(episodes.returns[index]))
            rows["observations"].append(episodes.observations[index][valid])
            rows["actions"].append(
                np.clip(episodes.actions[index][valid], env.action_low, env.action_high)
            )
            rows["confidence"].append(np.full(valid.sum(), confidence, np.float32))
            rows["trajectory_ids"].append(np.full(valid.sum(), len(trajectory_returns) - 1))
    return rows, trajectory_returns


# What normalizer.json holds (its name kept for the folders already written): the task and
# the normalised return's ends, the random and optimal returns.
RETURN_RANGE_KEYS = ("env", "random_return", "optimal_return")


def write_demonstrations(out: Path, demos: Demonstrations, return_range: dict) -> Path:
    """``normalizer.json`` (``return_range``: the task, the random and the optimal return),
    then ``demos.npz`` (the mark of a finished run), each written to a temporary sibling and
    renamed, so a kill never leaves a truncated file behind."""
    atomic_write_text(out / "normalizer.json", json.dumps(return_range, indent=2))
    path = out / DEMOS_FILE
    with atomic_path(path) as temporary:  # keeps the .npz suffix np.savez would append
        save_npz(temporary, demos)
    return path


def policies_table(picked: Picked) -> str:
    """The three policies' returns, raw and normalised, as a Markdown table."""
    best, intermediate = picked.optimal, picked.intermediate
    normalised = normalized_return(
        picked.intermediate_return, picked.random_return, picked.optimal_return
    )
    return (
        f"\n| policy | return | normalised |\n|---|---:|---:|\n"
        f"| random (uniform actions) | {picked.random_return:.1f} | 0.00 |\n"
        f"| optimal (iter {best.iteration}, seed {best.seed}) | "
        f"{picked.optimal_return:.1f} | 1.00 |\n"
        f"| intermediate (iter {intermediate.iteration}, seed {intermediate.seed}) | "
        f"{picked.intermediate_return:.1f} | {normalised:.2f} |"
    )
