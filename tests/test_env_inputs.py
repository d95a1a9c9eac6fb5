"""Bad environment options fail at ``envs.make`` with a ValueError naming the option and the
value, before any MuJoCo model is loaded (so no test here loads one)."""

import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.envs import gym_mujoco, mjx_tasks

MUJOCO_TASKS = ("Ant", "HalfCheetah", "Hopper", "Walker2d", "Swimmer", *envs.GYM_TASKS)


@pytest.fixture(autouse=True)
def no_model_loading(monkeypatch):
    """Loading a model (or importing MJX) fails the test: checks must come first."""

    def load(*args, **kwargs):
        raise AssertionError("a MuJoCo model was loaded before the options were checked")

    monkeypatch.setattr(mjx_tasks, "_brax_task", load)
    monkeypatch.setattr(mjx_tasks, "import_mjx", load)
    monkeypatch.setattr(gym_mujoco, "gymnasium_asset", load)
    monkeypatch.setattr(gym_mujoco, "import_mjx", load)


BAD_OPTIONS = [
    *[
        (
            name,
            {"max_episode_steps": value},
            rf"{name}: max_episode_steps must be a positive integer, got {text}",
        )
        for name in ("Pendulum-v1", *MUJOCO_TASKS)
        for value, text in ((0, "0"), (-5, "-5"), (2.5, "2.5"))
    ],
    ("Pendulum-v1", {"max_episode_steps": True}, "got True"),  # a bool is not a count
    ("Pendulum-v1", {"max_episode_steps": "200"}, "got '200'"),
    ("Pendulum-v1", {"g": float("nan")}, "Pendulum-v1: g must be a finite number > 0, got nan"),
    ("Pendulum-v1", {"g": float("inf")}, "g must be a finite number > 0, got inf"),
    ("Pendulum-v1", {"g": 0.0}, "g must be a finite number > 0, got 0.0"),
    ("Pendulum-v1", {"g": -9.8}, "g must be a finite number > 0, got -9.8"),
    ("Pendulum-v1", {"g": "9.8"}, "g must be a finite number > 0, got '9.8'"),
    *[
        (name, {option: value}, rf"{name}: {option} must be a positive integer, got {value}")
        for name in MUJOCO_TASKS
        for option, value in (("solver_iterations", 0), ("ls_iterations", 1.5))
    ],
    ("Hopper-v4", {"physics": "gpu"}, "Hopper-v4: physics must be one of c, mjx, warp, got 'gpu'"),
    ("Ant-v4", {"num_threads": 0}, "Ant-v4: num_threads must be a positive integer, got 0"),
    ("Ant-v4", {"num_threads": True}, "num_threads must be a positive integer, got True"),
    (
        "Walker2d-v4",
        {"terminate_when_unhealthy": 0},
        "Walker2d-v4: terminate_when_unhealthy must be True or False, got 0",
    ),
]


@pytest.mark.parametrize(("name", "options", "message"), BAD_OPTIONS)
def test_bad_builtin_options_are_named(name, options, message):
    with pytest.raises(ValueError, match=message):
        envs.make(name, **options)


def test_good_options_of_numpy_types_are_taken():
    env = envs.make("Pendulum-v1", g=np.float32(9.5), max_episode_steps=np.int64(50))
    assert (env.g, env.max_episode_steps) == (9.5, 50)
    assert type(env.max_episode_steps) is int


def test_from_brax_checks_its_time_limit_first():
    with pytest.raises(ValueError, match="fast: max_episode_steps must be a positive integer"):
        envs.from_brax(object(), name="fast", max_episode_steps=0)  # never looked at


class Tiny(envs.Env):
    """A factory that records being called; its env keeps whatever time limit it is given."""

    calls = 0

    def __init__(self, max_episode_steps=10):
        Tiny.calls += 1
        self.name = "Tiny"
        self.observation_size = self.action_size = 1
        self.action_low, self.action_high = np.array([-1.0]), np.array([1.0])
        self.max_episode_steps = max_episode_steps

    # Never reset or stepped: the test checks only what make() does while building it.
    def _reset(self, key):
        raise NotImplementedError

    def _step(self, internal, action):
        raise NotImplementedError


def test_custom_envs_get_the_same_checks(monkeypatch):
    monkeypatch.setattr(envs, "_REGISTRY", {})
    envs.register("Tiny-v0", Tiny)
    Tiny.calls = 0
    with pytest.raises(ValueError, match="Tiny-v0: max_episode_steps must be a positive integer"):
        envs.make("Tiny-v0", max_episode_steps=0)
    with pytest.raises(ValueError, match="got 2.5"):
        envs.make("tests.test_env_inputs:Tiny", max_episode_steps=2.5)
    assert Tiny.calls == 0  # refused before the factory ran
    # A factory that sets a bad limit itself is caught on what it returns.
    envs.register("Tiny-nan", lambda: Tiny(max_episode_steps=float("nan")))
    with pytest.raises(ValueError, match="Tiny-nan: max_episode_steps must be .* got nan"):
        envs.make("Tiny-nan")
    assert envs.make("Tiny-v0", max_episode_steps=3).max_episode_steps == 3
