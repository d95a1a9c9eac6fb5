import jax
import jax.numpy as jnp
import pytest

from pngail_jax import envs


def test_unknown_name_lists_available():
    with pytest.raises(ValueError, match="available: Pendulum-v1, Hopper-v4, .*, Ant, HalfCheetah"):
        envs.make("CartPole-v1")


def test_brax_variants_have_no_physics_choice():
    with pytest.raises(ValueError, match="unsupported option.*'physics'"):
        envs.make("Hopper", physics="c")  # Brax's variant runs on MJX only


def test_unknown_option_is_named():
    with pytest.raises(ValueError, match="unsupported option.*'gravity'"):
        envs.make("Pendulum-v1", gravity=9.8)


def test_bad_solver_option():
    with pytest.raises(ValueError, match="ls_iterations must be a positive integer"):
        envs.make("Swimmer", ls_iterations=0)


def test_non_numeric_action_is_a_clear_error():
    env = envs.make("Pendulum-v1")
    state = env.reset(jax.random.key(0))
    with pytest.raises(TypeError, match="real number array"):
        env.step(state, jnp.array([True]))


def test_options_reach_the_env():
    env = envs.make("Pendulum-v1", g=9.81, max_episode_steps=50)
    assert env.g == 9.81 and env.max_episode_steps == 50
