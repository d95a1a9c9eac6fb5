"""A tiny run of experiments.early_rewards, so the diagnostic cannot drift from the library."""

import json
import math

import pytest
from conftest import authors_data

from pngail_jax.jobs.early_rewards import EarlyRewardsConfig
from pngail_jax.jobs.early_rewards import early_rewards as early_rewards_job
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs import early_rewards

PENDULUM = authors_data() / "Pendulum-v1_mixture.npy"


@pytest.mark.skipif(not PENDULUM.exists(), reason=f"the authors' Pendulum set is not at {PENDULUM}")
def test_early_rewards_reads_every_variant_at_every_reading(tmp_path):
    out = tmp_path / "early.json"
    flags = ["--demos", str(PENDULUM), "--seeds", "1", "--iterations", "2", "--every", "1"]
    early_rewards.main([*flags, "--classifier-steps", "10", "--out", str(out)])
    readings = json.loads(out.read_text())["readings"]
    assert [(r["iteration"], r["variant"]) for r in readings] == [
        (iteration, label) for iteration in (1, 2) for label, _, _ in early_rewards.VARIANTS
    ]
    for reading in readings:
        # Pendulum's reward per step lies in [-(pi^2 + 0.1 * 8^2 + 0.001 * 2^2), 0], 200 steps
        assert -16.2736044 * 200 <= reading["eval_return"] <= 0, reading
        for side in ("optimal_rows", "intermediate_rows", "agent"):
            assert 0 < reading[f"reward_{side}"] < math.inf, reading  # sp(-z) > 0
    with pytest.raises(SystemExit, match=f"^early_rewards: {out} exists: choose another output"):
        early_rewards.main([*flags, "--out", str(out)])  # never over an existing file


def test_the_job_refuses_bad_settings_and_an_existing_file_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="iterations >= every"):
        EarlyRewardsConfig(str(PENDULUM), iterations=5, every=10)
    with pytest.raises(ValueError, match="classifier_steps"):
        EarlyRewardsConfig(str(PENDULUM), classifier_steps=0)
    with pytest.raises(SystemExit, match=r"iterations \(15\) must be a multiple of every \(10\)"):
        early_rewards.main(["--demos", str(PENDULUM), "--iterations", "15", "--every", "10"])
    existing = tmp_path / "early.json"
    existing.write_text("{}")
    with pytest.raises(RunError, match="exists"):
        early_rewards_job(EarlyRewardsConfig(str(PENDULUM)), existing)
    assert existing.read_text() == "{}"
    with pytest.raises(RunError, match="demonstrations"):
        early_rewards_job(EarlyRewardsConfig(str(tmp_path / "missing.npy")), tmp_path / "a.json")


@pytest.mark.skipif(not PENDULUM.exists(), reason=f"the authors' Pendulum set is not at {PENDULUM}")
def test_rewards_on_rows_are_each_sides_mean_policy_reward_against_numpy():
    """The job's reading of a discriminator: the mean of sp(-z) = log(1 + e^-z) over the
    optimal rows and over the others, per cell, against NumPy on the same logits."""
    import jax
    import numpy as np

    from pngail_jax.adversarial.family import ADVERSARIAL
    from pngail_jax.demos import load_demonstrations
    from pngail_jax.grid import Cell, stack_cells
    from pngail_jax.jobs.early_rewards import _build, rewards_on_rows

    config = EarlyRewardsConfig(str(PENDULUM), seeds=1, iterations=2, every=1, classifier_steps=10)
    demos = load_demonstrations(str(PENDULUM))
    trainer, _ = _build(config, demos)
    cells = [Cell("gail", 0), Cell("gail", 1)]
    state, _ = jax.jit(jax.vmap(trainer.init))(
        *stack_cells(cells, jax.random.key(0), family=ADVERSARIAL)
    )
    optimal = demos.confidence >= 1.0
    assert 0 < optimal.sum() < demos.num_rows
    on_optimal, on_other = rewards_on_rows(trainer, state, jax.numpy.asarray(optimal))
    for cell in range(2):
        params = jax.tree.map(lambda x, c=cell: x[c], state.discriminator_params)
        logits = np.asarray(trainer.discriminator.apply(params, trainer.demo_inputs), np.float64)
        reward = np.log1p(np.exp(-logits))
        np.testing.assert_allclose(on_optimal[cell], reward[optimal].mean(), rtol=1e-5)
        np.testing.assert_allclose(on_other[cell], reward[~optimal].mean(), rtol=1e-5)
    assert on_optimal[0] != on_optimal[1]  # two initialisations, two readings
