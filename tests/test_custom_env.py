"""Bringing your own environment: an ``Env`` subclass, a registered name, ``module:factory``
names, Brax environments, and the errors that name what is wrong."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.config.settings import REFERENCE_SETTINGS, settings_for

MODULE = "tests.test_custom_env"


class PointMass(envs.Env):
    """A 1-D point mass pushed by a force in [-1, 1]; reward -x^2; it terminates once
    within 0.05 of the origin. The example of docs/environments.md."""

    def __init__(self, max_episode_steps: int = 100, dt: float = 0.1):
        self.name = "PointMass"
        self.observation_size = 2  # position, velocity
        self.action_size = 1
        self.action_low = np.array([-1.0], np.float32)
        self.action_high = np.array([1.0], np.float32)
        self.max_episode_steps = max_episode_steps
        self.dt = dt

    def _reset(self, key):
        position = jax.random.uniform(key, minval=-1.0, maxval=1.0)
        obs = jnp.stack([position, 0.0])
        return obs, obs  # the observation is the whole state

    def _step(self, internal, action):
        position, velocity = internal
        velocity = velocity + self.dt * jnp.clip(action[0], -1.0, 1.0)
        position = position + self.dt * velocity
        obs = jnp.stack([position, velocity])
        return obs, -(position**2), jnp.abs(position) < 0.05, obs


class Incomplete(PointMass):
    def __init__(self):
        pass


def not_an_env():
    return {"observation_size": 2}


def make_fast(**options):
    from brax.envs.fast import Fast

    return Fast(**options)


@pytest.fixture
def registry(monkeypatch):
    """An empty registry of user environments for one test."""
    monkeypatch.setattr(envs, "_REGISTRY", {})


def test_module_factory_name_makes_a_vmappable_env():
    env = envs.make(f"{MODULE}:PointMass", max_episode_steps=1)
    assert type(env).__name__ == "PointMass" and env.max_episode_steps == 1
    auto = envs.AutoReset(env)
    state = jax.jit(jax.vmap(auto.reset))(jax.random.split(jax.random.key(0), 8))
    start = np.asarray(state.obs[:, 0])
    state = jax.jit(jax.vmap(auto.step))(state, jnp.ones((8, 1)))
    # One push of 1 for dt = 0.1: velocity 0.1, position start + 0.1 * 0.1, reward -x^2.
    position = start + 0.01
    np.testing.assert_allclose(state.final_obs, np.stack([position, np.full(8, 0.1)], 1), 1e-6)
    np.testing.assert_allclose(state.reward, -(position**2), rtol=1e-5)
    np.testing.assert_array_equal(state.done, np.abs(position) < 0.05)
    # The one-step limit ends every episode: the next ones start at rest.
    assert state.truncated.all() and (state.episode_length == 1).all()
    np.testing.assert_array_equal(state.obs[:, 1], 0.0)


def test_registered_factory(registry):
    envs.register("PointMass-v0", lambda max_episode_steps=10: PointMass(max_episode_steps))
    assert envs.is_known("PointMass-v0")
    env = envs.make("PointMass-v0", max_episode_steps=3)
    assert isinstance(env, PointMass) and env.max_episode_steps == 3
    with pytest.raises(ValueError, match="already registered.*overwrite=True"):
        envs.register("PointMass-v0", PointMass)
    envs.register("PointMass-v0", PointMass, overwrite=True)
    assert envs.make("PointMass-v0").max_episode_steps == 100
    with pytest.raises(ValueError, match="'Hopper' is a built-in environment"):
        envs.register("Hopper", PointMass, overwrite=True)
    with pytest.raises(ValueError, match="must be callable"):
        envs.register("Other", PointMass())
    with pytest.raises(ValueError, match="available: Pendulum-v1, .*, Swimmer, PointMass-v0"):
        envs.check_name("Pointmass-v0")


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("Hoper", r"unknown environment 'Hoper'; available: Pendulum-v1, .*package.module:factory"),
        ("no_such_module_x:make", r"cannot import 'no_such_module_x' \(No module named"),
        (f"{MODULE}:missing", r"module 'tests.test_custom_env' has no attribute 'missing'"),
        (f"{MODULE}:MODULE", r"has a non-callable attribute 'MODULE'"),
    ],
)
def test_unknown_names_are_named(name, message):
    assert not envs.is_known(name)
    with pytest.raises(ValueError, match=message):
        envs.check_name(name)
    with pytest.raises(ValueError, match=message):
        envs.make(name)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("PointMass", {"gravity": 1.0}, r"unsupported option in \['gravity'\].*'gravity'"),
        ("not_an_env", {}, r"not_an_env: the factory returned a dict, not a pngail_jax.envs.Env"),
        ("Incomplete", {}, r"does not set name, observation_size, action_size"),
    ],
)
def test_bad_factories_are_named(name, options, message):
    assert envs.is_known(f"{MODULE}:{name}")  # known: the error comes from building it
    with pytest.raises(ValueError, match=message):
        envs.make(f"{MODULE}:{name}", **options)


def test_custom_envs_get_the_reference_settings(registry):
    envs.register("PointMass-v0", PointMass)
    assert settings_for("PointMass-v0") == REFERENCE_SETTINGS
    assert settings_for(f"{MODULE}:PointMass", num_envs=4).num_envs == 4
    with pytest.raises(ValueError, match="unknown environment 'Hoper'"):
        settings_for("Hoper")


def test_brax_environments_are_wrapped():
    # Brax's own toy environment: a 1-D body that is rewarded for its position; no MuJoCo.
    env = envs.make(f"{MODULE}:make_fast")
    assert isinstance(env, envs.Env) and env.name == f"{MODULE}:make_fast"
    assert (env.observation_size, env.action_size, env.max_episode_steps) == (2, 1, 1000)
    np.testing.assert_array_equal([env.action_low, env.action_high], [[-1.0], [1.0]])
    state = jax.vmap(env.reset)(jax.random.split(jax.random.key(0), 3))
    state = jax.jit(jax.vmap(env.step))(state, jnp.ones((3, 1)))
    # One push: velocity dt = 0.02, position dt * velocity = 4e-4, the reward.
    np.testing.assert_allclose(state.obs, [[4e-4, 0.02]] * 3, rtol=1e-6)
    np.testing.assert_allclose(state.reward, [4e-4] * 3, rtol=1e-6)
    assert not state.done.any()
    wrapped = envs.from_brax(make_fast(), name="fast", max_episode_steps=7)
    assert (wrapped.name, wrapped.max_episode_steps) == ("fast", 7)
    with pytest.raises(ValueError, match="only flat array observations"):
        envs.from_brax(make_fast(obs_mode="dict_state"))


def test_a_user_environment_trains_through_the_public_api():
    """TRPO learns the point mass from its ``module:factory`` name: from a policy that lets
    the mass sit (return about -30 over 100 steps) to one that brings it home."""
    from pngail_jax.rl import PolicyTrainer, RolloutConfig, TRPOHyperparams

    env = envs.make(f"{MODULE}:PointMass")
    config = RolloutConfig(num_envs=10, unroll_length=100, num_iterations=30, eval_every=10)
    _, metrics = jax.jit(PolicyTrainer(config, env).train)(
        TRPOHyperparams.create(), jax.random.key(0)
    )
    evaluations = np.asarray(metrics["eval/return"])[9::10]
    assert evaluations[-1] > -5.0, evaluations
