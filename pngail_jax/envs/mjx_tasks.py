"""MuJoCo tasks on MJX: Brax's Ant, HalfCheetah, Hopper and Walker2d, and our own Swimmer.

Brax's tasks are used through its environment classes on the ``mjx`` backend (never through
its wrappers or training code); ``docs/environments.md`` lists how each differs from
gymnasium's version of the same task. Brax's own swimmer runs only on its ``generalized``
backend, so ``Swimmer`` is built here from the MuJoCo model that gymnasium ships, with
gymnasium's Swimmer-v5 observation, reward and reset. ``from_brax`` puts any other Brax
environment behind the same API.

MJX solver settings dominate CPU speed. ``solver_iterations`` and ``ls_iterations`` override
the model's (``FAST_SOLVER`` is the setting measured in ``docs/environments.md``); the default
keeps each task's own settings.
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax.envs.base import Env, check_positive_int

# Newton solver capped at 1 iteration and 4 line-search iterations: Brax's own setting for
# Ant on mjx. An opt-in speed option for the other tasks; its accuracy cost is measured in
# docs/environments.md.
FAST_SOLVER = {"solver_iterations": 1, "ls_iterations": 4}

BRAX_TASKS = {
    "Ant": "ant",
    "HalfCheetah": "halfcheetah",
    "Hopper": "hopper",
    "Walker2d": "walker2d",
}


def import_mjx():
    """Imports ``mujoco.mjx``, hiding its unconditional "Failed to import warp" prints.

    MJX prints those lines whenever the optional NVIDIA Warp backend is absent, which is
    always the case here; they are not errors.
    """
    with contextlib.redirect_stdout(io.StringIO()):
        from mujoco import mjx
    return mjx


def check_options(
    name: str, max_episode_steps: Any, solver_iterations: Any, ls_iterations: Any
) -> tuple[int, dict[str, int]]:
    """The checked time limit and the MJX solver overrides (``mujoco.MjOption`` field names
    to values), or a ValueError naming the bad option; called before any model is loaded."""
    max_episode_steps = check_positive_int(name, "max_episode_steps", max_episode_steps)
    solver = {}
    for field, option, value in (
        ("iterations", "solver_iterations", solver_iterations),
        ("ls_iterations", "ls_iterations", ls_iterations),
    ):
        if value is not None:
            solver[field] = check_positive_int(name, option, value)
    return max_episode_steps, solver


class BraxTask(Env):
    """A Brax environment behind the pngail-jax ``Env`` API: one of Brax's MuJoCo tasks on the
    ``mjx`` backend, or any Brax environment instance given as ``brax_env`` (``from_brax``).

    Args:
      name: one of ``BRAX_TASKS`` (``"Ant"``, ``"HalfCheetah"``, ``"Hopper"``, ``"Walker2d"``),
        or with ``brax_env`` any name for reports.
      max_episode_steps: time limit, a positive integer (1000, as gymnasium's versions).
      solver_iterations, ls_iterations: MJX solver overrides, positive integers; None keeps
        the task's own.
      brax_env: a Brax environment to wrap instead of building the task ``name``. Its
        observations must be flat arrays; its action bounds are its actuators' control range,
        or [-1, 1] (Brax's convention) when it has no ``sys``.
      **brax_options: passed to the Brax task (e.g. ``terminate_when_unhealthy``); not with
        ``brax_env``, which is built already.
    """

    def __init__(
        self,
        name: str,
        max_episode_steps: int = 1000,
        solver_iterations: int | None = None,
        ls_iterations: int | None = None,
        *,
        brax_env: Any = None,
        **brax_options: Any,
    ):
        max_episode_steps, solver = check_options(
            name, max_episode_steps, solver_iterations, ls_iterations
        )
        if brax_env is None:
            brax_env = _brax_task(name, brax_options)
        elif brax_options:
            raise ValueError(
                f"{name}: options {sorted(brax_options)} are for Brax's own tasks; pass them "
                "when you build your Brax environment"
            )
        if solver:
            brax_env.sys = brax_env.sys.tree_replace({f"opt.{k}": v for k, v in solver.items()})
        self._brax_env = brax_env
        self.name = name
        # Brax's own observation_size property runs an un-jitted reset (about 25 s on a CPU).
        raw_key = jax.ShapeDtypeStruct((2,), jnp.uint32)
        obs = jax.eval_shape(brax_env.reset, raw_key).obs
        if not isinstance(obs, jax.ShapeDtypeStruct) or obs.ndim != 1:
            raise ValueError(f"{name}: only flat array observations are supported, got {obs}")
        self.observation_size = int(obs.shape[0])
        self.action_size = int(brax_env.action_size)
        if hasattr(brax_env, "sys"):
            low, high = brax_env.sys.actuator.ctrl_range.T
        else:
            low, high = -np.ones(self.action_size), np.ones(self.action_size)
        self.action_low = np.asarray(low, np.float32)
        self.action_high = np.asarray(high, np.float32)
        self.max_episode_steps = max_episode_steps

    @property
    def dt(self) -> float:
        """Seconds per step (Brax ``PipelineEnv``s only)."""
        return float(self._brax_env.dt)

    @property
    def model_options(self) -> dict[str, Any]:
        """The MJX solver settings in use (for reports and benchmark tables)."""
        opt = self._brax_env.sys.opt
        return {
            "solver": int(opt.solver),
            "iterations": int(opt.iterations),
            "ls_iterations": int(opt.ls_iterations),
            "timestep": float(opt.timestep),
        }

    def _reset(self, key):
        brax_state = self._brax_env.reset(key)
        return brax_state.obs, brax_state

    def _step(self, internal, action):
        brax_state = self._brax_env.step(internal, action)
        return brax_state.obs, brax_state.reward, brax_state.done > 0, brax_state


def _brax_task(name: str, brax_options: dict[str, Any]):
    """Brax's environment of the task ``name`` on the ``mjx`` backend."""
    import_mjx()
    from brax import envs as brax_envs

    try:
        with warnings.catch_warnings():
            # Brax warns on every model load that it is not maintained; we only use its task
            # definitions, on MJX, which is.
            warnings.filterwarnings("ignore", "Brax System, piplines", UserWarning)
            return brax_envs.get_environment(BRAX_TASKS[name], backend="mjx", **brax_options)
    except TypeError as error:
        raise ValueError(f"{name}: unsupported option in {sorted(brax_options)}: {error}") from None


def from_brax(brax_env: Any, name: str | None = None, max_episode_steps: int = 1000) -> BraxTask:
    """Any Brax environment (a ``brax.envs.base.Env`` instance, e.g. from
    ``brax.envs.get_environment``) as an ``Env``; ``name`` defaults to its class name. Brax's
    own wrappers (auto-reset, episode limits) are not needed: ``max_episode_steps`` sets
    ``truncated`` and ``AutoReset`` restarts episodes."""
    return BraxTask(
        name or type(brax_env).__name__, max_episode_steps=max_episode_steps, brax_env=brax_env
    )


def gymnasium_asset(file_name: str) -> str:
    import gymnasium.envs.mujoco

    return os.path.join(os.path.dirname(gymnasium.envs.mujoco.__file__), "assets", file_name)


class Swimmer(Env):
    """gymnasium's Swimmer-v5 on MJX (float32), from gymnasium's own ``swimmer.xml``.

    Observation ``[qpos[2:], qvel]`` (8 values), reward ``x_velocity - 1e-4 * |action|^2`` with
    ``x_velocity`` the finite difference of ``qpos[0]`` over ``dt = 4 * 0.01``, reset
    ``qpos0 + U(-0.1, 0.1)``, ``U(-0.1, 0.1)`` velocities, no termination, 1000-step limit.
    As in gymnasium the control cost uses the action as given, while the simulator clamps
    the control to [-1, 1]. Options (positive integers): ``max_episode_steps``,
    ``solver_iterations`` and ``ls_iterations``.
    """

    frame_skip = 4
    forward_reward_weight = 1.0
    ctrl_cost_weight = 1e-4
    reset_noise_scale = 0.1

    def __init__(
        self,
        max_episode_steps: int = 1000,
        solver_iterations: int | None = None,
        ls_iterations: int | None = None,
    ):
        max_episode_steps, solver = check_options(
            "Swimmer", max_episode_steps, solver_iterations, ls_iterations
        )
        import mujoco

        mjx = import_mjx()
        mj_model = mujoco.MjModel.from_xml_path(gymnasium_asset("swimmer.xml"))
        for field, value in solver.items():
            setattr(mj_model.opt, field, value)
        self._mjx = mjx
        self._model = mjx.put_model(mj_model)
        self._init_qpos = np.asarray(mj_model.qpos0, np.float32)
        self.name = "Swimmer"
        self.observation_size = mj_model.nq + mj_model.nv - 2
        self.action_size = mj_model.nu
        self.action_low = np.asarray(mj_model.actuator_ctrlrange[:, 0], np.float32)
        self.action_high = np.asarray(mj_model.actuator_ctrlrange[:, 1], np.float32)
        self.max_episode_steps = max_episode_steps
        self.dt = float(mj_model.opt.timestep) * self.frame_skip
        self.model_options = {
            "solver": int(mj_model.opt.solver),
            "iterations": int(mj_model.opt.iterations),
            "ls_iterations": int(mj_model.opt.ls_iterations),
            "timestep": float(mj_model.opt.timestep),
        }

    def data_from(self, qpos: jax.Array, qvel: jax.Array):
        """MJX data at the given joint positions and velocities, like gymnasium's set_state."""
        data = self._mjx.make_data(self._model)
        data = data.replace(
            qpos=jnp.asarray(qpos, data.qpos.dtype), qvel=jnp.asarray(qvel, data.qvel.dtype)
        )
        return self._mjx.forward(self._model, data)

    def observe(self, data) -> jax.Array:
        return jnp.concatenate([data.qpos[2:], data.qvel])

    def _reset(self, key):
        qpos_key, qvel_key = jax.random.split(key)
        scale = self.reset_noise_scale
        nq, nv = self._model.nq, self._model.nv
        qpos = self._init_qpos + jax.random.uniform(qpos_key, (nq,), minval=-scale, maxval=scale)
        qvel = jax.random.uniform(qvel_key, (nv,), minval=-scale, maxval=scale)
        data = self.data_from(qpos, qvel)
        return self.observe(data), data

    def _step(self, data, action):
        x_before = data.qpos[0]
        data = data.replace(ctrl=action.astype(data.ctrl.dtype))
        data = jax.lax.fori_loop(
            0, self.frame_skip, lambda _, d: self._mjx.step(self._model, d), data
        )
        x_velocity = (data.qpos[0] - x_before) / self.dt
        reward = self.forward_reward_weight * x_velocity - self.ctrl_cost_weight * jnp.sum(
            jnp.square(action)
        )
        return self.observe(data), reward.astype(data.qpos.dtype), False, data
