"""Functional, jittable, vmappable environments.

    env = envs.make("Pendulum-v1")
    state = jax.vmap(env.reset)(jax.random.split(key, 16))
    state = jax.vmap(env.step)(state, actions)          # actions: float[16, env.action_size]

``make(name, **options)`` knows ``Pendulum-v1`` (pure JAX, equal to gymnasium's), ``Ant``,
``HalfCheetah``, ``Hopper``, ``Walker2d`` (Brax on MJX) and ``Swimmer`` (gymnasium's Swimmer-v5
on MJX). ``AutoReset(env)`` restarts finished episodes.
"""

from __future__ import annotations

from pngail_jax.envs.autoreset import AutoReset, AutoResetState
from pngail_jax.envs.base import Env, EnvState
from pngail_jax.envs.mjx_tasks import BRAX_TASKS, FAST_SOLVER

__all__ = ["ENV_NAMES", "FAST_SOLVER", "AutoReset", "AutoResetState", "Env", "EnvState", "make"]

ENV_NAMES = ("Pendulum-v1", *BRAX_TASKS, "Swimmer")


def make(name: str, **options) -> Env:
    """Builds the environment ``name`` with its ``options``.

    Options: ``max_episode_steps`` for every env; ``g`` for Pendulum-v1; ``solver_iterations``
    and ``ls_iterations`` (MJX solver overrides, see ``FAST_SOLVER``) for the MuJoCo tasks,
    plus any Brax environment keyword for the Brax ones. Building a MuJoCo task loads the
    model (a second or two); compiling its step takes 10-60 s on a CPU.
    """
    if name == "Pendulum-v1":
        from pngail_jax.envs.pendulum import Pendulum

        return _build(Pendulum, name, options)
    if name in BRAX_TASKS:
        from pngail_jax.envs.mjx_tasks import BraxTask

        return BraxTask(name, **options)
    if name == "Swimmer":
        from pngail_jax.envs.mjx_tasks import Swimmer

        return _build(Swimmer, name, options)
    raise ValueError(f"unknown environment {name!r}; available: {', '.join(ENV_NAMES)}")


def _build(env_class, name: str, options: dict) -> Env:
    try:
        return env_class(**options)
    except TypeError as error:
        raise ValueError(f"{name}: unsupported option in {sorted(options)}: {error}") from None
