"""API tests every environment must pass, on one compiled vmapped rollout per environment.

Compiling a MuJoCo task takes 20-40 s on a 2-core CPU, so each environment compiles one
function once (a class-scoped fixture): two parallel slots, reset, then a little more than
one full episode of auto-reset steps under random actions (20% beyond the action bounds, so
the environments' clipping runs too). Every assertion below reads that one trace. One class
per environment lets ``pytest -n 2 --dist loadscope`` compile two environments at once. The
MJX tasks run with a 100-step time limit (each MJX step is milliseconds on a CPU, and the
contract is about the limit set, whatever it is); gymnasium's tasks on the C engine and
Pendulum-v1 keep their own 1000 and 200.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs

NUM_SLOTS = 2
MJX_OPTIONS = {"max_episode_steps": 100}
EXTRA_STEPS = 5  # past max_episode_steps, so every slot resets at least once


def _rollout(env, key):
    auto = envs.AutoReset(env)
    num_steps = env.max_episode_steps + EXTRA_STEPS
    low, high = 1.2 * env.action_low, 1.2 * env.action_high

    def one_slot(key):
        reset_key, action_key = jax.random.split(key)
        first = auto.reset(reset_key)
        actions = jax.random.uniform(
            action_key, (num_steps, env.action_size), minval=low, maxval=high
        )

        def body(state, action):
            state = auto.step(state, action)
            return state, state

        _, trace = jax.lax.scan(body, first, actions)
        return first, trace

    return jax.jit(jax.vmap(one_slot))(jax.random.split(key, NUM_SLOTS))


class EnvContract:
    env_name: str
    options: dict = {}  # noqa: RUF012  (read only)

    @pytest.fixture(scope="class")
    @classmethod
    def rollout(cls):
        env = envs.make(cls.env_name, **cls.options)
        first, trace = _rollout(env, jax.random.key(0))
        return env, jax.device_get(first), jax.device_get(trace)

    def test_attributes(self, rollout):
        env, _, _ = rollout
        assert env.observation_size > 0 and env.action_size > 0
        assert env.action_low.shape == env.action_high.shape == (env.action_size,)
        assert np.all(env.action_low < env.action_high)
        assert env.max_episode_steps > 0

    def test_shapes_and_dtypes(self, rollout):
        env, first, trace = rollout
        num_steps = env.max_episode_steps + EXTRA_STEPS
        assert first.obs.shape == (NUM_SLOTS, env.observation_size)
        assert (
            trace.obs.shape == trace.final_obs.shape == (NUM_SLOTS, num_steps, env.observation_size)
        )
        for field in ("reward", "done", "truncated", "episode_return", "episode_length"):
            assert getattr(trace, field).shape == (NUM_SLOTS, num_steps), field
        assert trace.done.dtype == trace.truncated.dtype == np.bool_
        assert trace.episode_length.dtype == np.int32
        assert trace.obs.dtype == trace.reward.dtype == np.float32

    def test_finite_under_random_actions(self, rollout):
        _, first, trace = rollout
        assert np.isfinite(first.obs).all()
        assert np.isfinite(trace.obs).all() and np.isfinite(trace.final_obs).all()
        assert np.isfinite(trace.reward).all()

    def test_slots_differ(self, rollout):
        _, first, _ = rollout
        assert not np.allclose(first.obs[0], first.obs[1])

    def test_truncation_at_max_episode_steps(self, rollout):
        env, _, trace = rollout
        np.testing.assert_array_equal(
            trace.truncated, trace.episode_length == env.max_episode_steps
        )
        assert trace.episode_length.max() == env.max_episode_steps or trace.done.any()
        finished = trace.done | trace.truncated
        assert finished.any(axis=1).all(), "every slot must finish an episode"

    def test_episode_bookkeeping(self, rollout):
        """Counters restart after each finished episode and sum the episode's own rewards."""
        _, _, trace = rollout
        for slot in range(NUM_SLOTS):
            finished = trace.done[slot] | trace.truncated[slot]
            start = 0
            for end in np.flatnonzero(finished):
                lengths = trace.episode_length[slot, start : end + 1]
                np.testing.assert_array_equal(lengths, np.arange(1, end - start + 2))
                np.testing.assert_allclose(
                    trace.episode_return[slot, end],
                    trace.reward[slot, start : end + 1].sum(),
                    rtol=1e-4,
                    atol=1e-3,
                )
                start = end + 1

    def test_auto_reset_keeps_final_obs_and_draws_new_starts(self, rollout):
        _, first, trace = rollout
        finished = trace.done | trace.truncated
        # Away from episode ends, obs is the observation the step reached.
        np.testing.assert_array_equal(trace.obs[~finished], trace.final_obs[~finished])
        for slot in range(NUM_SLOTS):
            starts = [first.obs[slot], *trace.obs[slot][finished[slot]]]
            ends = trace.final_obs[slot][finished[slot]]
            assert len(starts) >= 2
            # Each new episode starts from a fresh draw of the reset distribution: neither the
            # slot's first start (Brax's own wrapper would return there) nor the final state.
            for new_start in starts[1:]:
                assert not np.allclose(new_start, starts[0])
            for new_start, end in zip(starts[1:], ends, strict=True):
                assert not np.allclose(new_start, end)

    def test_wrong_action_shape_is_a_clear_error(self, rollout):
        env, first, _ = rollout
        # Slot 0's first state from the trace: an eager reset of a MuJoCo task runs MJX op by
        # op (a minute on a CPU); the shape check fires before any computation.
        state = jax.tree.map(lambda leaf: leaf[0], first)
        auto = envs.AutoReset(env)
        with pytest.raises(ValueError, match=rf"action must have shape \({env.action_size},\)"):
            auto.step(state, jnp.zeros(env.action_size + 1))
        with pytest.raises(ValueError, match="jax.vmap"):
            auto.step(state, jnp.zeros((4, env.action_size)))


class TestPendulum(EnvContract):
    env_name = "Pendulum-v1"


@pytest.mark.heavy
class TestAnt(EnvContract):
    env_name = "Ant"
    options = MJX_OPTIONS


@pytest.mark.heavy
class TestHalfCheetah(EnvContract):
    env_name = "HalfCheetah"
    options = MJX_OPTIONS


@pytest.mark.heavy
class TestHopper(EnvContract):
    env_name = "Hopper"
    options = MJX_OPTIONS


@pytest.mark.heavy
class TestWalker2d(EnvContract):
    env_name = "Walker2d"
    options = MJX_OPTIONS


@pytest.mark.heavy
class TestSwimmer(EnvContract):
    env_name = "Swimmer"
    options = MJX_OPTIONS


# gymnasium's tasks on the C engine (the tests run on a CPU): no XLA physics to compile.
class TestHopperV4(EnvContract):
    env_name = "Hopper-v4"


class TestHalfCheetahV4(EnvContract):
    env_name = "HalfCheetah-v4"


class TestWalker2dV4(EnvContract):
    env_name = "Walker2d-v4"


class TestSwimmerV4(EnvContract):
    env_name = "Swimmer-v4"


class TestAntV4(EnvContract):
    env_name = "Ant-v4"


class TestHopperV5(EnvContract):
    env_name = "Hopper-v5"


class TestHalfCheetahV5(EnvContract):
    env_name = "HalfCheetah-v5"


class TestWalker2dV5(EnvContract):
    env_name = "Walker2d-v5"


class TestSwimmerV5(EnvContract):
    env_name = "Swimmer-v5"


class TestAntV5(EnvContract):
    env_name = "Ant-v5"


def test_every_environment_has_a_contract_class():
    assert {cls.env_name for cls in EnvContract.__subclasses__()} == set(envs.ENV_NAMES)
