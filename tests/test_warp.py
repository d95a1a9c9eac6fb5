"""gymnasium's -v4 tasks on MuJoCo Warp (``physics="warp"``, MJX's ``impl="warp"``), on the CPU.

Warp is an optional extra (``pip install "pngail-jax[warp]"``): without it these tests skip,
as on CI. Its first kernel build takes about a minute (cached in ``~/.cache/warp``).

Warp computes in float32, so a whole episode cannot follow gymnasium's float64 one step for
step: rounding grows through contacts (MJX's JAX implementation parts from gymnasium the same
way, tests/test_gym_mujoco.py). The comparison over whole episodes is per transition: from each
state of gymnasium's episode, with its action, one step of ours against gymnasium's.
"""

import json

import gymnasium as gym
import jax
import numpy as np
import pytest
from test_gym_mujoco import _gymnasium_episode, _our_episode, sweep_resumes_bit_exactly

from pngail_jax import envs
from pngail_jax.envs.autoreset import AutoReset

pytest.importorskip("mujoco_warp", reason="MuJoCo Warp is an optional extra: pngail-jax[warp]")
pytestmark = pytest.mark.heavy  # Warp's kernels, and a MuJoCo model compile per test

EPISODE_STEPS = 1000

# Largest |difference| from gymnasium over the observation entries of 1,000 transitions, and
# the 99th percentile; measured (Warp / MJX's JAX implementation, 2026-12-05): Hopper 2.6e-6,
# Swimmer 7.2e-6, Walker2d 2.0e-4, HalfCheetah 7.1e-3 / 3.5e-3 (p99 4.6e-5), Ant 1.3 / 1.3
# (p99 4.3e-2): Ant's and HalfCheetah's contacts amplify the float32 rounding of the state
# equally on both float32 engines.
TRANSITION_TOLERANCE = {
    "Hopper-v4": (1e-5, 1e-5),
    "Swimmer-v4": (3e-5, 1e-5),
    "Walker2d-v4": (1e-3, 2e-4),
    "HalfCheetah-v4": (3e-2, 2e-4),
    "Ant-v4": (3.0, 0.1),
}


def _gymnasium_transitions(name: str, seed: int):
    """Every transition of gymnasium's episodes over ``EPISODE_STEPS`` steps of uniform
    actions up to 1.2x the bounds, a new episode after a termination: (qpos, qvel) before
    the step, action, observation, reward, terminated."""
    reference = gym.make(name).unwrapped
    reference.reset(seed=seed)
    rng = np.random.default_rng(seed)
    low, high = reference.action_space.low, reference.action_space.high
    rows = []
    for _ in range(EPISODE_STEPS):
        qpos, qvel = reference.data.qpos.copy(), reference.data.qvel.copy()
        action = rng.uniform(1.2 * low, 1.2 * high)
        obs, reward, terminated, _, _ = reference.step(action)
        rows.append((qpos, qvel, action, obs, reward, terminated))
        if terminated:
            reference.reset(seed=int(rng.integers(2**30)))
    return [np.array(column) for column in zip(*rows, strict=True)]


def _transitions(env, qpos, qvel, actions):
    """One step of ``env`` from each (qpos, qvel) with its action, every transition at once."""

    def one(qpos, qvel, action):
        obs, internal = env.state_at(qpos, qvel)
        state = env.reset(jax.random.key(0)).replace(obs=obs, internal=internal)
        state = env.step(state, action)
        return state.obs, state.reward, state.done

    as32 = (np.asarray(x, np.float32) for x in (qpos, qvel, actions))
    return [np.asarray(x) for x in jax.jit(jax.vmap(one))(*as32)]


@pytest.mark.parametrize("name", sorted(TRANSITION_TOLERANCE))
def test_every_transition_of_whole_episodes_follows_gymnasium(name):
    qpos, qvel, actions, obs, rewards, terminated = _gymnasium_transitions(name, 3)
    env = envs.make(name, physics="warp", warp_batch=len(qpos))
    our_obs, our_rewards, our_terminated = _transitions(env, qpos, qvel, actions)
    largest, p99 = TRANSITION_TOLERANCE[name]
    errors = np.abs(our_obs - obs)
    assert errors.max() <= largest, errors.max()
    assert np.quantile(errors, 0.99) <= p99, np.quantile(errors, 0.99)
    assert np.abs(our_rewards - rewards).max() <= max(largest, 1e-4)
    np.testing.assert_array_equal(our_terminated, terminated)


@pytest.mark.parametrize(
    "name, tolerance", [("Hopper-v4", 1e-4), ("Swimmer-v4", 1e-4), ("Walker2d-v4", 5e-4)]
)
def test_the_first_50_steps_follow_gymnasium(name, tolerance):
    """Stepped from its own states, as training runs it (measured over 50 steps: Swimmer
    7.6e-6, Walker2d 1.2e-4; HalfCheetah and Ant part as on MJX, see the module's note)."""
    qpos, qvel, actions, obs, rewards, terminated = _gymnasium_episode(name, 3, num_steps=50)
    env = envs.make(name, physics="warp", warp_batch=1)
    our_obs, our_rewards, our_terminated = _our_episode(env, qpos, qvel, actions.astype(np.float32))
    np.testing.assert_allclose(our_obs, obs, rtol=0, atol=tolerance)
    np.testing.assert_allclose(our_rewards, rewards, rtol=0, atol=tolerance)
    np.testing.assert_array_equal(our_terminated, terminated)


def _rollout(env, keys, num_steps=120):
    """Auto-reset rollout of one env per key, random actions: (obs, reward, done)."""

    def run(key):
        def body(state, step_key):
            action = jax.random.uniform(step_key, (env.action_size,), minval=-1, maxval=1)
            state = env.step(state, action)
            return state, (state.obs, state.reward, state.done)

        state = env.reset(key)
        return jax.lax.scan(body, state, jax.random.split(jax.random.fold_in(key, 1), num_steps))[1]

    return [np.asarray(x) for x in jax.jit(jax.vmap(run))(keys)]


def test_a_batch_equals_its_envs_one_at_a_time_and_repeats_bit_identically():
    """Hopper-v4 (contacts and terminations) under AutoReset: four envs stepped together
    (one shared contact buffer) equal each stepped alone, bit for bit; the same keys give the
    same run."""
    keys = jax.random.split(jax.random.key(7), 4)
    batch = _rollout(AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=4)), keys)
    assert batch[2].any(), "no episode ended: the test would not cover auto-resets"
    again = _rollout(AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=4)), keys)
    alone_env = AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=1))
    for column, repeated in zip(batch, again, strict=True):
        np.testing.assert_array_equal(column, repeated)
    for index in range(len(keys)):
        alone = _rollout(alone_env, keys[index : index + 1])
        for column, single in zip(batch, alone, strict=True):
            np.testing.assert_array_equal(column[index], single[0])


def test_a_full_contact_buffer_gives_nan_not_a_wrong_step():
    """64 Hopper envs on a buffer sized for one (Warp's 48 contacts for Hopper): the steps
    that lost contacts say so."""
    keys = jax.random.split(jax.random.key(0), 64)
    obs, reward, _ = _rollout(envs.make("Hopper-v4", physics="warp", warp_batch=1), keys, 20)
    assert np.isnan(reward).any() and np.isnan(obs).any()
    sized = _rollout(envs.make("Hopper-v4", physics="warp", warp_batch=64), keys, 20)
    assert np.isfinite(sized[0]).all() and np.isfinite(sized[1]).all()


def test_bad_options_are_refused_in_one_line():
    with pytest.raises(ValueError, match="warp_batch must be a positive integer"):
        envs.make("Hopper-v4", physics="warp", warp_batch=0)
    with pytest.raises(ValueError, match="warp_batch is an option of physics='warp' only"):
        envs.make("Hopper-v4", physics="mjx", warp_batch=4)
    with pytest.raises(ValueError, match="observes contact forces"):
        envs.make("Ant-v5", physics="warp")


def test_sweep_on_warp_resumes_bit_exactly(tmp_path):
    whole = sweep_resumes_bit_exactly(tmp_path, "warp")
    assert json.loads((whole / "config.json").read_text())["resolved"]["physics"] == "warp"
