"""Functional, jittable, vmappable environments.

    env = envs.make("Pendulum-v1")
    state = jax.vmap(env.reset)(jax.random.split(key, 16))
    state = jax.vmap(env.step)(state, actions)          # actions: float[16, env.action_size]

``make(name, **options)`` knows ``Pendulum-v1`` (pure JAX, equal to gymnasium's), gymnasium's
MuJoCo tasks ``Hopper-v4``, ``HalfCheetah-v4``, ``Walker2d-v4``, ``Swimmer-v4`` and ``Ant-v4``
and their -v5 (exact, on MuJoCo's C engine on a CPU or on MJX: ``gym_mujoco``),
Brax's variants ``Ant``, ``HalfCheetah``, ``Hopper``, ``Walker2d`` (on MJX) and ``Swimmer``
(gymnasium's Swimmer-v5 on MJX), the names given to ``register`` and
``"package.module:factory"``, your own ``Env`` or Brax environment (``docs/environments.md``,
"Bring your own environment").
``AutoReset(env)`` restarts finished episodes.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import sys
from collections.abc import Callable
from typing import Any

from pngail_jax.envs.autoreset import AutoReset, AutoResetState
from pngail_jax.envs.base import Env, EnvState, check_positive_int
from pngail_jax.envs.gym_mujoco import PHYSICS, TASKS, available_physics, default_physics
from pngail_jax.envs.mjx_tasks import BRAX_TASKS, FAST_SOLVER, from_brax

__all__ = [
    "ENV_NAMES",
    "FAST_SOLVER",
    "GYM_TASKS",
    "PHYSICS",
    "available_physics",
    "AutoReset",
    "AutoResetState",
    "Env",
    "EnvState",
    "check_name",
    "default_physics",
    "from_brax",
    "is_known",
    "task_family",
    "make",
    "register",
]

# gymnasium's MuJoCo tasks, exactly (physics: MuJoCo's C engine or MJX).
GYM_TASKS = tuple(TASKS)
ENV_NAMES = ("Pendulum-v1", *GYM_TASKS, *BRAX_TASKS, "Swimmer")

# Factories given to ``register``, by name.
_REGISTRY: dict[str, Callable[..., Any]] = {}


def make(name: str, **options) -> Env:
    """Builds the environment ``name`` with its ``options``.

    ``name``: a built-in (``ENV_NAMES``), a name given to ``register``, or
    ``"package.module:factory"``, which imports ``package.module`` and calls its ``factory``
    (an ``Env`` subclass or a function returning an ``Env``) with the options. A factory
    may return a Brax environment instead: it is wrapped with ``from_brax``.

    Built-in options: ``max_episode_steps`` for every env; ``g`` for Pendulum-v1;
    ``solver_iterations`` and ``ls_iterations`` (solver overrides, see ``FAST_SOLVER``) for
    the MuJoCo tasks; ``physics`` (``"c"``, ``"mjx"``, ``"warp"``, None: from the platform),
    ``num_threads`` (C engine) and ``warp_batch`` (Warp) for gymnasium's; any Brax
    environment keyword for Brax's. Building a MuJoCo task loads the model (a second or
    two); compiling its step takes 10-60 s on a CPU.

    Options are checked before anything is built: ``max_episode_steps``, ``solver_iterations``
    and ``ls_iterations`` must be positive integers and ``g`` a finite number > 0, else a
    ValueError names the option and the value. Whatever the factory, the environment made
    must have a positive integer ``max_episode_steps``.
    """
    if name == "Pendulum-v1":
        from pngail_jax.envs.pendulum import Pendulum

        return _build(Pendulum, name, options)
    if name in TASKS:
        from pngail_jax.envs.gym_mujoco import GymMujocoTask

        return _build(functools.partial(GymMujocoTask, name), name, options)
    if name in BRAX_TASKS:
        from pngail_jax.envs.mjx_tasks import BraxTask

        return BraxTask(name, **options)
    if name == "Swimmer":
        from pngail_jax.envs.mjx_tasks import Swimmer

        return _build(Swimmer, name, options)
    factory = _factory(name)
    if "max_episode_steps" in options:  # refused before the factory runs, as the built-ins do
        check_positive_int(name, "max_episode_steps", options["max_episode_steps"])
    try:
        env = _build(factory, name, options)
    except ValueError:
        raise
    except Exception as error:  # the user's code failed: one line naming it, chained
        raise ValueError(f"{name}: the factory raised {type(error).__name__}: {error}") from error
    return _as_env(name, env)


def register(name: str, factory: Callable[..., Any], *, overwrite: bool = False) -> None:
    """Makes ``make(name, **options)`` return ``factory(**options)``.

    ``factory``: an ``Env`` subclass, or a function returning an ``Env`` or a Brax
    environment. A built-in name cannot be registered; registering a name again raises
    unless ``overwrite``.
    """
    if name in ENV_NAMES:
        raise ValueError(f"{name!r} is a built-in environment: register yours under another name")
    if name in _REGISTRY and not overwrite:
        raise ValueError(f"{name!r} is already registered (pass overwrite=True to replace it)")
    if not callable(factory):
        raise ValueError(f"the factory of {name!r} must be callable, got {factory!r}")
    _REGISTRY[name] = factory


def task_family(name: str) -> str:
    """The task a name runs, whichever variant: ``"Hopper"`` for ``"Hopper-v4"`` and
    ``"Hopper-v5"`` (gymnasium's) and ``"Hopper"`` (Brax's); any other name as it is.
    Per-task tables (the paper's demonstration counts, classifier settings, Table 1) are keyed
    by it."""
    return name.rsplit("-v", 1)[0] if name in GYM_TASKS else name


def check_name(name: str) -> None:
    """Raises ValueError unless ``make`` knows ``name``: a built-in, a registered name, or a
    ``"package.module:factory"`` whose module imports and has that attribute (not called)."""
    if name not in ENV_NAMES:
        _factory(name)


def is_known(name: str) -> bool:
    """Whether ``check_name(name)`` passes."""
    try:
        check_name(name)
    except ValueError:
        return False
    return True


def _factory(name: str) -> Callable[..., Any]:
    """The registered or imported factory of a name that is not a built-in."""
    if name in _REGISTRY:
        return _REGISTRY[name]
    module_name, _, attribute = name.partition(":")
    if not (module_name and attribute):
        available = ", ".join((*ENV_NAMES, *_REGISTRY))
        raise ValueError(
            f"unknown environment {name!r}; available: {available}, or your own as "
            "'package.module:factory' (docs/environments.md)"
        )
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(
            f"{name}: cannot import {module_name!r} ({error}); is its directory on PYTHONPATH?"
        ) from None
    factory = getattr(module, attribute, None)
    if not callable(factory):
        problem = "no attribute" if factory is None else "a non-callable attribute"
        raise ValueError(f"{name}: module {module_name!r} has {problem} {attribute!r}")
    return factory


def _build(factory: Callable[..., Any], name: str, options: dict) -> Any:
    # Binding first names a wrong option without catching TypeErrors raised inside the factory.
    try:
        inspect.signature(factory).bind(**options)
    except TypeError as error:
        raise ValueError(f"{name}: unsupported option in {sorted(options)}: {error}") from None
    return factory(**options)


def _as_env(name: str, env: Any) -> Env:
    # A Brax environment can only exist once brax is imported: no import needed to check.
    brax_base = sys.modules.get("brax.envs.base")
    if brax_base is not None and isinstance(env, brax_base.Env):
        return from_brax(env, name=name)
    if not isinstance(env, Env):
        raise ValueError(
            f"{name}: the factory returned a {type(env).__name__}, not a pngail_jax.envs.Env "
            "or a Brax environment"
        )
    missing = [attribute for attribute in Env.__annotations__ if not hasattr(env, attribute)]
    if missing:
        raise ValueError(f"{name}: the environment does not set {', '.join(missing)}")
    check_positive_int(name, "max_episode_steps", env.max_episode_steps)
    return env
