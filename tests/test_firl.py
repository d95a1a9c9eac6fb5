"""f-IRL as its codebase runs it (pngail_jax.adversarial.firl, the f-IRL networks of
pngail_jax.networks): each loss, network and optimiser step against an independent NumPy
computation of its formula, the discriminator's refit, the demonstration segments, and the
config."""

import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.adversarial import firl
from pngail_jax.adversarial.methods import method_spec, stack
from pngail_jax.adversarial.trainer import AdversarialConfig, AdversarialTrainer
from pngail_jax.config.run_config import RunConfig
from pngail_jax.demos import Demonstrations
from pngail_jax.jobs.trainer_configs import adversarial_config
from pngail_jax.networks import ClampedStateReward, ResidualDiscriminator
from pngail_jax.rl import RolloutConfig

RNG = np.random.default_rng(0)


def softplus(x):
    return np.logaddexp(0.0, x)


def numpy_h(log_ratio, divergence):
    """h of f_div_disc.py: exp(l) (fkl), l (rkl), softplus(l) (js)."""
    return {"fkl": np.exp(log_ratio), "rkl": log_ratio, "js": softplus(log_ratio)}[divergence]


COEFS = {"fkl": (1, 0, 0), "rkl": (0, 1, 0), "js": (0, 0, 1)}


@pytest.mark.parametrize("divergence", ["fkl", "rkl", "js"])
def test_reward_loss_with_expert_segments_matches_numpy(divergence):
    """loss = ((t1 t2).mean - t1.mean t2.mean) / T over agent and expert segments, with
    t1 = -sum_t h(l) and t2 = sum_t theta . s (a linear reward); its gradient is
    (1/T) (mean(t1 phi) - mean(t1) mean(phi)), phi = sum_t s."""
    steps, num_agent, num_expert, size = 5, 4, 4, 3
    states = RNG.normal(size=(steps, num_agent + num_expert, size))
    log_ratio = RNG.uniform(-3, 3, size=(steps, num_agent + num_expert))
    theta = RNG.normal(size=size)

    def loss(theta):
        h = firl.divergence_h(jnp.asarray(log_ratio, jnp.float32), *COEFS[divergence])
        rewards = jnp.asarray(states, jnp.float32) @ theta  # float[T, N]
        return firl.covariance_surrogate(h.sum(axis=0), rewards.sum(axis=0), steps)[0]

    value, gradient = jax.value_and_grad(loss)(jnp.asarray(theta, jnp.float32))
    t1 = -numpy_h(log_ratio, divergence).sum(axis=0)  # float[N]
    phi = states.sum(axis=0)  # float[N, O]
    t2 = phi @ theta
    np.testing.assert_allclose(value, ((t1 * t2).mean() - t1.mean() * t2.mean()) / steps, rtol=1e-4)
    expected = ((t1[:, None] * phi).mean(0) - t1.mean() * phi.mean(0)) / steps
    np.testing.assert_allclose(gradient, expected, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("divergence", ["fkl", "rkl", "js"])
def test_a_reward_step_raises_the_expert_segments_reward_over_the_agents(divergence):
    """Expert states at s = +1 with a high log ratio, agent states at s = -1 with a low one:
    minimising the loss (a step against its gradient) makes r(s) = theta s larger on the
    expert's segments than on the agent's, for every divergence (each h increases in l)."""
    steps, num = 4, 3
    states = np.concatenate([-np.ones((steps, num, 1)), np.ones((steps, num, 1))], axis=1)
    log_ratio = np.concatenate([np.full((steps, num), -2.0), np.full((steps, num), 2.0)], axis=1)
    log_ratio += RNG.normal(scale=0.1, size=log_ratio.shape)
    h = firl.divergence_h(jnp.asarray(log_ratio, jnp.float32), *COEFS[divergence])

    def loss(theta):
        rewards = jnp.asarray(states, jnp.float32) @ theta
        return firl.covariance_surrogate(h.sum(axis=0), rewards.sum(axis=0), steps)[0]

    gradient = jax.grad(loss)(jnp.zeros(1))
    assert gradient[0] < 0  # -gradient points to a larger reward at s = +1, the expert's


@pytest.mark.parametrize(
    ("divergence", "f"),
    [
        ("fkl", lambda u: u * np.log(u)),
        ("rkl", lambda u: -np.log(u)),
        ("js", lambda u: u * np.log(u) - (1 + u) * np.log((1 + u) / 2)),
    ],
)
def test_minus_h_is_f_minus_u_f_prime_up_to_a_constant(divergence, f):
    """t1 = -sum h is the paper's sum h_f, h_f(u) = f(u) - u f'(u), up to a constant."""
    u = np.exp(RNG.uniform(-2, 2, size=50))
    step = 1e-6
    h_f = f(u) - u * (f(u + step) - f(u - step)) / (2 * step)
    h = np.asarray(firl.divergence_h(jnp.log(jnp.asarray(u, jnp.float32)), *COEFS[divergence]))
    offset = h_f - (-h.astype(np.float64))  # a constant, which the covariance ignores
    np.testing.assert_allclose(offset, offset.mean(), atol=2e-4)


def test_discriminator_loss_is_bce_with_logits_over_both_batches():
    expert, agent = RNG.normal(size=7) * 3, RNG.normal(size=5) * 3
    loss, _ = firl.state_discriminator_loss(jnp.asarray(expert), jnp.asarray(agent))
    logits = np.concatenate([expert, agent])
    targets = np.concatenate([np.ones(7), np.zeros(5)])
    probability = 1 / (1 + np.exp(-logits))
    bce = -(targets * np.log(probability) + (1 - targets) * np.log(1 - probability))
    np.testing.assert_allclose(loss, bce.mean(), rtol=1e-5)  # a mean over all 12 logits


def test_weight_decay_is_torch_adams_coupled_l2():
    """Two steps of torch's Adam(lr, weight_decay): g <- g + wd theta, then Adam's moments
    and bias corrections. A parameter with a zero loss gradient moves by lr sign(theta) on
    the first step (decoupled decay, AdamW, would move it by lr wd theta)."""
    learning_rate, weight_decay = 0.1, 0.3
    theta = np.array([0.5, -2.0, 1.5])
    grads = [np.array([0.0, 0.4, -1.0]), np.array([0.0, -0.2, 3.0])]
    optimizer = firl.adam_with_l2(learning_rate, weight_decay)
    params = jnp.asarray(theta, jnp.float32)
    state = optimizer.init(params)
    m = v = np.zeros(3)
    expected = theta.copy()
    for step, grad in enumerate(grads, start=1):
        updates, state = optimizer.update(jnp.asarray(grad, jnp.float32), state, params)
        params = params + updates
        g = grad + weight_decay * expected
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g**2
        m_hat, v_hat = m / (1 - 0.9**step), v / (1 - 0.999**step)
        expected = expected - learning_rate * m_hat / (np.sqrt(v_hat) + 1e-8)
        if step == 1:
            np.testing.assert_allclose(params[0], 0.5 - learning_rate, atol=1e-6)
        np.testing.assert_allclose(params, expected, rtol=1e-5)


def dense(params, x):
    return x @ np.asarray(params["kernel"]) + np.asarray(params["bias"])


def test_networks_are_theirs_and_clamped():
    """The forward passes in NumPy: the discriminator Linear, x + tanh(Linear x) per block,
    Linear; the reward Linear, Linear + ReLU, Linear (one nonlinearity); both clamped to
    [-10, 10], with no gradient where clamped."""
    states = RNG.normal(size=(6, 3)).astype(np.float32)
    discriminator = ResidualDiscriminator(hidden_size=8, num_residual_blocks=2)
    params = discriminator.init(jax.random.key(0), states[0])["params"]
    assert [np.shape(params[f"Dense_{i}"]["kernel"]) for i in range(4)] == [
        (3, 8), (8, 8), (8, 8), (8, 1)
    ]  # fmt: skip
    x = dense(params["Dense_0"], states)
    for i in (1, 2):
        x = x + np.tanh(dense(params[f"Dense_{i}"], x))
    expected = dense(params["Dense_3"], x)[:, 0]
    logits = discriminator.apply({"params": params}, states)
    np.testing.assert_allclose(logits, expected, rtol=1e-5, atol=1e-6)
    # PyTorch's default biases, U(+-1/sqrt(fan_in)), not zeros.
    assert np.all(np.abs(params["Dense_0"]["bias"]) <= 1 / np.sqrt(3)) and np.any(
        params["Dense_0"]["bias"] != 0
    )

    reward = ClampedStateReward(hidden_sizes=(8, 8))
    reward_params = reward.init(jax.random.key(1), states[0])["params"]
    hidden = np.maximum(dense(reward_params["Dense_1"], dense(reward_params["Dense_0"], states)), 0)
    expected = dense(reward_params["Dense_2"], hidden)[:, 0]
    np.testing.assert_allclose(
        reward.apply({"params": reward_params}, states), expected, rtol=1e-5, atol=1e-6
    )

    far = jnp.asarray(1e4 * RNG.normal(size=(50, 3)), jnp.float32)
    networks = ((discriminator, {"params": params}), (reward, {"params": reward_params}))
    for network, variables in networks:
        outputs = np.asarray(network.apply(variables, far))
        assert np.all(np.abs(outputs) <= 10.0) and np.any(np.abs(outputs) == 10.0)
        gradient = jax.grad(lambda x, n=network, v=variables: n.apply(v, x).sum())(far)
        clamped = np.abs(outputs) == 10.0
        assert np.all(np.asarray(gradient)[clamped] == 0.0)


def test_discriminator_refit_separates_states_and_is_warm_started():
    """Expert states around +1, agent states around -1: the refit's loss falls over its
    iterations, its logits take the right signs, and a second refit continues the Adam
    state (its step count adds up)."""
    expert = RNG.normal(loc=1.0, scale=0.3, size=(40, 2)).astype(np.float32)
    agent = RNG.normal(loc=-1.0, scale=0.3, size=(60, 2)).astype(np.float32)
    network = ResidualDiscriminator(hidden_size=16, num_residual_blocks=1)
    params = network.init(jax.random.key(0), expert[0])
    optimizer = firl.adam_with_l2(3e-3, 1e-4)
    fit = jax.jit(firl.fit_discriminator, static_argnums=(0, 1, 6, 7))
    args = (jnp.asarray(expert), jnp.asarray(agent), 60, 16)
    params, state, losses = fit(
        network.apply, optimizer, params, optimizer.init(params), *args, jax.random.key(1)
    )
    assert losses.shape == (60,)
    assert losses[-10:].mean() < 0.5 * losses[:10].mean()
    assert np.all(network.apply(params, expert) > 0) and np.all(network.apply(params, agent) < 0)
    _, state, more = fit(network.apply, optimizer, params, state, *args, jax.random.key(2))
    assert int(state[1].count) == 120  # scale_by_adam's count: 60 + 60 steps
    assert more.mean() < losses[:10].mean()


def test_segments_are_consecutive_rows_of_resampled_trajectories():
    sample = jax.jit(firl.sample_segment_rows, static_argnums=(2, 3))
    ids = np.array([5, 5, 5, 2, 2, 7, 7, 7, 7, 5])  # the last row joins trajectory 5
    source = firl.SegmentSource.of_trajectories(ids)
    np.testing.assert_array_equal(source.rows, [0, 1, 2, 9, 3, 4, 5, 6, 7, 8])
    np.testing.assert_array_equal(source.starts, [0, 4, 6])
    np.testing.assert_array_equal(source.lengths, [4, 2, 4])
    rows = np.asarray(sample(jax.random.key(0), source, 3, 3))
    assert rows.shape == (3, 3)
    stream = list(np.asarray(source.rows))
    trajectories = []
    for segment in rows.T:
        first = stream.index(segment[0])
        np.testing.assert_array_equal(segment, [stream[(first + t) % 10] for t in range(3)])
        trajectory = int(np.searchsorted([0, 4, 6], first, side="right") - 1)
        length, start = [4, 2, 4][trajectory], [0, 4, 6][trajectory]
        # A uniform start where 3 steps fit; a 2-step trajectory's segment starts at its first.
        assert first - start <= max(length - 3, 0)
        trajectories.append(trajectory)
    assert sorted(trajectories) == [0, 1, 2]  # 3 of 3: drawn without replacement
    # More segments than trajectories: drawn with replacement.
    assert np.asarray(sample(jax.random.key(1), source, 5, 2)).shape == (2, 5)
    # Without trajectory ids: consecutive entries of the split's rows, wrapping at the end.
    split_rows = jnp.array([11, 4, 8, 0, 6], jnp.int32)
    rows = np.asarray(sample(jax.random.key(2), firl.SegmentSource.of_rows(split_rows), 4, 7))
    order = list(np.asarray(split_rows))
    for segment in rows.T:
        first = order.index(segment[0])
        np.testing.assert_array_equal(segment, [order[(first + t) % 5] for t in range(7)])


def test_config_is_the_codebases_and_checked():
    config = firl.FirlConfig()
    assert (config.discriminator_iterations, config.discriminator_batch_size) == (1200, 800)
    assert (config.discriminator_learning_rate, config.discriminator_weight_decay) == (3e-4, 1e-4)
    assert (config.reward_learning_rate, config.reward_weight_decay) == (1e-4, 1e-3)
    assert config.reward_hidden_sizes == (64, 64) and config.discriminator_residual_blocks == 2
    ant = firl.FirlConfig.for_env("Ant")
    assert ant.discriminator_residual_blocks == 5 and ant.reward_hidden_sizes == (128, 128)
    assert adversarial_config(RunConfig(env="Ant")).firl == ant
    assert adversarial_config(RunConfig(env="Hopper")).firl == config
    with pytest.raises(ValueError, match="discriminator_iterations"):
        firl.FirlConfig(discriminator_iterations=0)
    with pytest.raises(ValueError, match="reward_weight_decay"):
        firl.FirlConfig(reward_weight_decay=-1.0)


def test_the_trainers_reward_rises_on_the_demonstrations_without_trajectory_ids():
    """End to end through ``firl.outer_step`` on rows without trajectory ids
    (segments of consecutive split rows): demonstration states around +1, agent states
    around -1; after a few outer steps the reward is higher on the demonstrations', for each
    divergence, and the discriminator's logit is a positive log ratio there."""
    rng = np.random.default_rng(1)
    demos = Demonstrations(
        observations=rng.normal(1.0, 0.3, size=(60, 3)).astype(np.float32),
        actions=np.zeros((60, 1), np.float32),
    )
    config = AdversarialConfig(
        rollout=RolloutConfig(num_envs=4, unroll_length=25, num_iterations=1, eval_every=1),
        phases=("firl",),
        firl=firl.FirlConfig(
            discriminator_iterations=20, discriminator_batch_size=32, reward_learning_rate=1e-2
        ),
    )
    trainer = AdversarialTrainer(config, envs.make("Pendulum-v1"), demos)
    phase = trainer.phases.get(firl.FirlPhase)
    assert phase.segments is None
    agent_obs = jnp.asarray(rng.normal(-1.0, 0.3, size=(25, 4, 3)), jnp.float32)
    demo_rows = jnp.arange(40, dtype=jnp.int32)  # a split of 40 of the 60 rows

    def outer_steps(spec, key):
        firl_state = phase.initial_state(3, key)

        def step(firl_state, key):
            state = types.SimpleNamespace(firl=firl_state, demo_rows=demo_rows)
            return phase.outer_step(trainer.phases.context, spec, state, agent_obs, key)

        return jax.lax.scan(step, firl_state, jax.random.split(key, 15))

    run = jax.jit(jax.vmap(outer_steps))
    specs = stack([method_spec(name) for name in ("firl-fkl", "firl-rkl", "firl-js")])
    firl_state, metrics = run(specs, jax.random.split(jax.random.key(0), 3))
    assert np.all(np.asarray(metrics["firl/log_ratio_expert"][:, -1]) > 0)
    assert np.all(np.asarray(metrics["firl/log_ratio_agent"][:, -1]) < 0)
    assert np.all(
        np.asarray(metrics["firl/disc_loss"][:, -1] < metrics["firl/disc_loss_first"][:, 0])
    )
    gap = metrics["firl/reward_expert"] - metrics["firl/reward_agent"]  # float[3, 15]
    assert np.all(np.asarray(gap[:, -1]) > np.asarray(gap[:, 0]))
    assert np.all(np.asarray(gap[:, -1]) > 0)
