"""Learning test of the adversarial trainer: GAIL imitates the authors' optimal trajectory."""

from pathlib import Path

import jax
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import Demonstrations, load_demonstrations
from pngail_jax.grid import make_cells, stack_cells
from pngail_jax.rl import TRPOConfig
from pngail_jax.train import AdversarialConfig, AdversarialTrainer

SHARED_PENDULUM = Path(__file__).resolve().parents[2] / "shared" / "data" / "pendulum"


@pytest.mark.skipif(
    not SHARED_PENDULUM.exists(), reason=f"the authors' Pendulum set is not at {SHARED_PENDULUM}"
)
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
