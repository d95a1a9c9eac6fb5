"""Learning tests of the adversarial trainer: GAIL imitates an optimal trajectory (a classical
controller's, made here; and the authors', where their file is present)."""

import dataclasses

import chex
import jax
import numpy as np
import pytest
from conftest import authors_data, swing_up_demonstrations

from pngail_jax import envs
from pngail_jax.adversarial import AdversarialConfig, AdversarialTrainer
from pngail_jax.bc import BCConfig
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import Demonstrations, load_demonstrations
from pngail_jax.grid import make_cells, stack_cells
from pngail_jax.methods import required_phases
from pngail_jax.ranking import RankingConfig
from pngail_jax.rl import TRPOConfig

SHARED_PENDULUM = authors_data()


@pytest.mark.skipif(
    not (SHARED_PENDULUM / "Pendulum-v1_mixture.npy").exists(),
    reason=f"the authors' Pendulum set is not in {SHARED_PENDULUM}",
)
@pytest.mark.slow
def test_gail_learns_pendulum_from_the_optimal_trajectory():
    """Rows 0-199 of the released set come from the optimal policy (r = 1). From random
    (about -1200), GAIL's final return after 150 iterations varies a lot between seeds, and a
    float rounding difference (another CPU, another XLA version) acts like a new seed: 16
    seeds of this configuration ended between -570 and -142 (median -228) here. The bar is on
    the median of 4 seeds (about 60 s on 2 cores), so it fails only if two of them end worse
    than every seed measured."""
    env = envs.make("Pendulum-v1")
    released = load_demonstrations(SHARED_PENDULUM / "Pendulum-v1_mixture.npy", action_scale=2.0)
    optimal = Demonstrations(
        released.observations[:200], released.actions[:200], released.confidence[:200]
    )
    np.testing.assert_array_equal(optimal.confidence, 1.0)
    config = AdversarialConfig(
        trpo=TRPOConfig(num_iterations=150, eval_every=10, fisher="gauss_newton"),
        classifier=ClassifierConfig(num_steps=100),  # GAIL reads no confidences
    )
    trainer = AdversarialTrainer(config, env, optimal)
    cells = make_cells(["gail"], num_seeds=4)
    _, metrics = jax.jit(jax.vmap(trainer.train))(*stack_cells(cells, jax.random.key(0)))
    final = np.asarray(metrics["eval/return"])[:, -1]
    assert np.median(final) > -600, final
    assert np.isfinite(np.asarray(metrics["disc/loss"])).all()


@pytest.mark.slow
def test_gail_learns_pendulum_from_a_controllers_trajectory():
    """The same learning test on a file-free trajectory, so it runs everywhere (CI has no
    authors' files): one 200-step episode of the hand-written swing-up controller of
    conftest (return -123 on seed 0; random is about -1200). GAIL, 4 seeds x 150
    iterations; the bar is on the median, as above. Measured here: keys 0 and 1 (8 seeds)
    ended between -656 and -183, medians -215 and -275."""
    optimal, returns = swing_up_demonstrations(num_episodes=1, seed=0)
    assert optimal.num_rows == 200 and returns[0] > -200
    config = AdversarialConfig(
        trpo=TRPOConfig(num_iterations=150, eval_every=10, fisher="gauss_newton"),
        classifier=ClassifierConfig(num_steps=100),  # GAIL reads no confidences
    )
    trainer = AdversarialTrainer(config, envs.make("Pendulum-v1"), optimal)
    cells = make_cells(["gail"], num_seeds=4)
    _, metrics = jax.jit(jax.vmap(trainer.train))(*stack_cells(cells, jax.random.key(0)))
    final = np.asarray(metrics["eval/return"])[:, -1]
    assert np.median(final) > -600, final


@pytest.mark.slow
def test_demonstration_actions_reach_every_learned_comparison_clipped_as_the_agents():
    """The agent's actions reach the discriminator clipped to the bounds (what the physics
    applies), so the demonstrations' must too: otherwise |a| > bound alone tells them apart
    (the authors' MuJoCo files have such rows in 70-94% of cases). A set with actions up to
    1.5x the bound must train exactly as the same set clipped to the bound, in the
    discriminator (GAIL), WGAIL's weights (refreshed every iteration here), behaviour cloning
    and CAIL's ranked trajectories."""
    rng = np.random.default_rng(0)
    actions = rng.uniform(-3, 3, size=(200, 1)).astype(np.float32)  # Pendulum's bound: 2
    beyond = Demonstrations(
        observations=rng.normal(size=(200, 3)).astype(np.float32),
        actions=actions,
        confidence=np.repeat([1.0, 0.6, 0.3, 0.1], 50).astype(np.float32),
        trajectory_ids=np.repeat(np.arange(4), 50),
    )
    inside = dataclasses.replace(beyond, actions=np.clip(actions, -2, 2))
    methods = ("gail", "wgail", "bc", "cail")
    config = AdversarialConfig(
        trpo=TRPOConfig(
            num_envs=4, unroll_length=25, num_iterations=2, eval_every=1, num_eval_episodes=1,
            num_value_minibatches=5,
        ),
        classifier=ClassifierConfig(num_steps=20),
        wgail_refresh_every=1,
        phases=required_phases(methods),
        ranking=RankingConfig(num_steps=20, snippet_length=10),
        bc=BCConfig(num_steps=20, batch_size=16),
    )  # fmt: skip
    env = envs.make("Pendulum-v1")
    assert AdversarialTrainer(config, env, beyond).num_clipped_rows == (np.abs(actions) > 2).sum()
    inputs = stack_cells(make_cells(methods, 1), jax.random.key(0))
    results = [
        jax.jit(jax.vmap(AdversarialTrainer(config, env, data).train))(*inputs)
        for data in (beyond, inside)
    ]
    (state_beyond, metrics_beyond), (state_inside, metrics_inside) = results
    for name in ("disc/loss", "eval/return", "train/reward"):
        np.testing.assert_array_equal(metrics_beyond[name], metrics_inside[name], err_msg=name)
    chex.assert_trees_all_equal(state_beyond, state_inside)
    assert np.all(np.asarray(state_beyond.importance_weights) != 1.0)  # WGAIL's w refreshed
