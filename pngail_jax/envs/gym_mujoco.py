"""gymnasium's MuJoCo tasks (-v4 and -v5), exactly, on MuJoCo's C engine, on MJX or on MJX's Warp.

``Hopper-v4``, ``HalfCheetah-v4``, ``Walker2d-v4``, ``Swimmer-v4`` and ``Ant-v4`` are
gymnasium's tasks of those names: the same model files (read from the installed gymnasium),
frame skip, observation, reward terms, termination and reset noise. They are the closest
available to the paper's gym -v2 tasks (mujoco-py), which used the same model files.
``Hopper-v5``, ``HalfCheetah-v5``, ``Walker2d-v5``, ``Swimmer-v5`` and ``Ant-v5`` are
gymnasium's current versions (those of Minari's MuJoCo datasets), with their own model file,
healthy reward and contact forces where they have them.

One task, three physics engines (``physics=``):

- ``"c"``: MuJoCo's own C engine in float64, as gymnasium runs it. The physics state travels
  through JAX as the float64 bytes of MuJoCo's state vector (time, positions, velocities and
  the solver's warm start) viewed as ``uint32``, so it is exact whatever JAX's float width,
  and ``step`` is a ``jax.pure_callback`` batched over every env of a grid at once: one
  call per time step steps all of them on a pool of threads (MuJoCo releases the GIL) and
  computes their observations, rewards and terminations in float64 with gymnasium's
  formulas, rounded to JAX's width only on the way out.
  ``mujoco.rollout`` is not used because it does not return the solver's warm start: without
  it HalfCheetah-v4 drifted from gymnasium by 16 (largest position or velocity difference)
  within one episode.
- ``"mjx"``: MJX (its JAX implementation), in JAX's float width, for accelerators.
- ``"warp"``: MJX on MuJoCo Warp (``impl="warp"``), float32 kernels on an NVIDIA GPU or,
  for development, on the CPU; an optional extra (``pip install "pngail-jax[warp]"``).
  Warp keeps one contact buffer for the whole batch, sized at Warp's own capacity for one
  env times ``warp_batch`` (the most envs stepped together); an overflow gives NaN.
- ``None`` (default): ``"c"`` when JAX's default backend is the CPU, else ``"mjx"``.

Observations, rewards and terminations are written once (``TaskSpec``, ``outcome``) against
an array namespace, NumPy for the C engine and ``jax.numpy`` for MJX.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.envs.base import Env, float_dtype
from pngail_jax.envs.mjx_tasks import check_options, gymnasium_asset, import_mjx

PHYSICS = ("c", "mjx", "warp")
WARP_EXTRA = 'pip install "pngail-jax[warp]"'


# Task functions act on the last axis, so the C engine's host code runs them on a whole batch.


def _healthy_hopper(xp, qpos, qvel):
    # gymnasium: every state entry but x and z strictly inside (-100, 100), 0.7 < z < inf,
    # -0.2 < torso angle < 0.2 (a NaN fails every comparison).
    rest = xp.concatenate([qpos[..., 2:], qvel], axis=-1)
    z, angle = qpos[..., 1], qpos[..., 2]
    in_range = xp.all((rest > -100.0) & (rest < 100.0), axis=-1)
    return in_range & (z > 0.7) & (z < xp.inf) & (angle > -0.2) & (angle < 0.2)


def _healthy_walker(xp, qpos, qvel):
    z, angle = qpos[..., 1], qpos[..., 2]
    return (z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0)


def _healthy_ant(xp, qpos, qvel):
    # Ant's range is inclusive, unlike Hopper's and Walker2d's.
    finite = xp.all(xp.isfinite(qpos), axis=-1) & xp.all(xp.isfinite(qvel), axis=-1)
    return finite & (qpos[..., 2] >= 0.2) & (qpos[..., 2] <= 1.0)


def _observe_clipped_velocity(xp, qpos, qvel):
    return xp.concatenate([qpos[..., 1:], xp.clip(qvel, -10.0, 10.0)], axis=-1)


def _observe_from(start: int):
    def observe(xp, qpos, qvel):
        return xp.concatenate([qpos[..., start:], qvel], axis=-1)

    return observe


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One gymnasium -v4 or -v5 task, as data.

    Reward: ``x_velocity + healthy_reward - ctrl_cost_weight * |action|^2`` with
    ``x_velocity = (x_after - x_before) / dt``, ``dt = timestep * frame_skip``. ``x`` is
    ``qpos[0]``, except where ``position_body`` names a body: then it is that body's frame
    position from MuJoCo's last forward pass (gymnasium's ``get_body_com``), which after a
    step lags the state by one substep. Terminating -v4 tasks pay ``healthy_reward`` on every
    step, the last one included, as gymnasium's -v4 do with ``terminate_when_unhealthy``;
    -v5 tasks pay it on healthy steps only (``healthy_reward_on_every_step`` False), so not on
    the step that terminates.
    Reset: ``qpos0 + U(-s, s)`` and ``U(-s, s)`` (or ``s * N(0, 1)``) velocities.

    Attributes:
      xml: gymnasium's model file name.
      frame_skip: physics steps per environment step.
      ctrl_cost_weight: weight of the squared action (as given, before MuJoCo clamps it).
      reset_noise_scale: ``s`` above.
      normal_velocity_noise: velocities ``s * N(0, 1)`` (HalfCheetah, Ant), else ``U(-s, s)``.
      observe: ``(xp, qpos, qvel) -> obs``; ``xp`` is ``numpy`` or ``jax.numpy``.
      healthy: ``(xp, qpos, qvel) -> bool``, or None for a task that never terminates.
      healthy_reward: reward per step of a terminating task.
      position_body: see above.
      healthy_reward_on_every_step: see above (True for -v4, False for -v5).
      contact_cost_weight: with it (Ant-v5), the task reads MuJoCo's external contact forces
        on every body after the step (``cfrc_ext``, from ``mj_rnePostConstraint``, as
        gymnasium computes them), clipped to [-1, 1]: the observation ends with those of
        every body but the world, and the reward pays ``contact_cost_weight`` times their
        squared sum. 0: the task reads none.
    """

    xml: str
    frame_skip: int
    ctrl_cost_weight: float
    reset_noise_scale: float
    normal_velocity_noise: bool
    observe: Callable
    healthy: Callable | None = None
    healthy_reward: float = 0.0
    position_body: str | None = None
    healthy_reward_on_every_step: bool = True
    contact_cost_weight: float = 0.0

    @property
    def reads_contact_forces(self) -> bool:
        return self.contact_cost_weight > 0


def outcome(xp, spec: TaskSpec, terminate_when_unhealthy: bool, dt: float, step: dict):
    """``(obs, reward, terminated)`` of a step, gymnasium's formulas on the last axis.

    ``step``: ``qpos``, ``qvel`` after the step, ``x_before`` / ``x_after`` (the positions
    the forward velocity reads) and ``action`` as given, and for a task that reads them
    ``contact_forces`` (every body's six, world first, flattened); arrays of the namespace
    ``xp``.
    """
    qpos, qvel, action = step["qpos"], step["qvel"], step["action"]
    forward_reward = (step["x_after"] - step["x_before"]) / dt
    ctrl_cost = spec.ctrl_cost_weight * xp.sum(xp.square(action), axis=-1)
    terminated = xp.zeros_like(forward_reward, dtype=bool)
    rewards = forward_reward
    if spec.healthy is not None:
        healthy = spec.healthy(xp, qpos, qvel)
        if terminate_when_unhealthy:
            terminated = ~healthy
        if terminate_when_unhealthy and spec.healthy_reward_on_every_step:
            rewards = rewards + spec.healthy_reward
        else:
            rewards = rewards + xp.where(healthy, spec.healthy_reward, 0.0)
    obs = spec.observe(xp, qpos, qvel)
    if spec.reads_contact_forces:
        forces = xp.clip(step["contact_forces"], -1.0, 1.0)
        contact_cost = spec.contact_cost_weight * xp.sum(xp.square(forces), axis=-1)
        # gymnasium's order of operations, so that float64 rewards agree to the last bit.
        obs = xp.concatenate([obs, forces[..., 6:]], axis=-1)
        return obs, rewards - (ctrl_cost + contact_cost), terminated
    # gymnasium's order of operations, so that float64 rewards agree to the last bit.
    return obs, rewards - ctrl_cost, terminated


TASKS: dict[str, TaskSpec] = {
    "Hopper-v4": TaskSpec(
        "hopper.xml", 4, 1e-3, 5e-3, False, _observe_clipped_velocity, _healthy_hopper, 1.0
    ),
    "HalfCheetah-v4": TaskSpec("half_cheetah.xml", 5, 0.1, 0.1, True, _observe_from(1)),
    "Walker2d-v4": TaskSpec(
        "walker2d.xml", 4, 1e-3, 5e-3, False, _observe_clipped_velocity, _healthy_walker, 1.0
    ),
    "Swimmer-v4": TaskSpec("swimmer.xml", 4, 1e-4, 0.1, False, _observe_from(2)),
    "Ant-v4": TaskSpec(
        "ant.xml", 5, 0.5, 0.1, True, _observe_from(2), _healthy_ant, 1.0, position_body="torso"
    ),
}
# gymnasium's -v5 tasks: Hopper, Walker2d and Ant pay the healthy reward on healthy steps
# only; Walker2d-v5 has its own model file (both feet with friction 0.9; -v4's left foot has
# 1.9); Ant-v5 observes the bodies' contact forces and pays a contact cost; HalfCheetah-v5 and
# Swimmer-v5 step, observe and reward as their -v4.
TASKS |= {
    "Hopper-v5": dataclasses.replace(TASKS["Hopper-v4"], healthy_reward_on_every_step=False),
    "HalfCheetah-v5": TASKS["HalfCheetah-v4"],
    "Walker2d-v5": dataclasses.replace(
        TASKS["Walker2d-v4"], xml="walker2d_v5.xml", healthy_reward_on_every_step=False
    ),
    "Swimmer-v5": TASKS["Swimmer-v4"],
    "Ant-v5": dataclasses.replace(
        TASKS["Ant-v4"], healthy_reward_on_every_step=False, contact_cost_weight=5e-4
    ),
}


def default_physics() -> str:
    """``"c"`` when JAX computes on the CPU, else ``"mjx"`` (an accelerator)."""
    return "c" if jax.default_backend() == "cpu" else "mjx"


def check_physics(name: str, physics: Any) -> str:
    """The engine ``physics`` names (None: ``default_physics()``), or a ValueError."""
    if physics is None:
        return default_physics()
    if physics not in PHYSICS:
        raise ValueError(f"{name}: physics must be one of {', '.join(PHYSICS)}, got {physics!r}")
    return physics


@struct.dataclass
class CState:
    """Physics state of one environment on the C engine.

    Attributes:
      bits: uint32[2 * (state_size + 1)], the float64 bytes of MuJoCo's state vector
        (``mjSTATE_FULLPHYSICS | mjSTATE_WARMSTART``) followed by the ``x`` that the next
        step's velocity starts from.
    """

    bits: jax.Array


@struct.dataclass
class MjxState:
    """Physics state of one environment on MJX: its ``mjx.Data`` and the next step's start ``x``."""

    data: Any
    x: jax.Array


class GymMujocoTask(Env):
    """A gymnasium -v4 or -v5 MuJoCo task (``TASKS``) on the C engine or on MJX.

    Args:
      name: a key of ``TASKS``.
      max_episode_steps: time limit, a positive integer (1000, gymnasium's).
      solver_iterations, ls_iterations: solver caps, positive integers; None keeps the model's
        (gymnasium's). Any other value departs from gymnasium.
      physics: ``"c"``, ``"mjx"``, ``"warp"`` or None (from the platform,
        ``default_physics``).
      num_threads: threads of the C engine (default: the CPUs this process may use).
      warp_batch: on ``"warp"``, the most envs stepped together (every env of every cell
        of a grid, or of its evaluation): Warp's contact buffer is shared by the whole
        batch and sized for that many (default ``WARP_DEFAULT_BATCH``). A step that
        overflows it returns NaN observations and rewards, never quietly wrong ones.
      terminate_when_unhealthy: gymnasium's option of that name: False never terminates and
        pays the healthy reward only on healthy steps (for measuring full-length episodes).
    """

    def __init__(
        self,
        name: str,
        max_episode_steps: int = 1000,
        solver_iterations: int | None = None,
        ls_iterations: int | None = None,
        physics: str | None = None,
        num_threads: int | None = None,
        terminate_when_unhealthy: bool = True,
        warp_batch: int | None = None,
    ):
        max_episode_steps, solver = check_options(
            name, max_episode_steps, solver_iterations, ls_iterations
        )
        self.physics = check_physics(name, physics)
        _check_engine_options(name, num_threads, terminate_when_unhealthy)
        self.warp_batch = _check_warp_batch(name, self.physics, warp_batch)
        self.terminate_when_unhealthy = terminate_when_unhealthy
        import mujoco

        self.spec = TASKS[name]
        model = mujoco.MjModel.from_xml_path(gymnasium_asset(self.spec.xml))
        for field, value in solver.items():
            setattr(model.opt, field, value)
        self.name = name
        # A task that reads contact forces observes those of every body but the world.
        self._num_contact_forces = 6 * (model.nbody - 1) if self.spec.reads_contact_forces else 0
        self.observation_size = self._num_contact_forces + int(
            jax.eval_shape(
                functools.partial(self.spec.observe, jnp),
                jax.ShapeDtypeStruct((model.nq,), jnp.float32),
                jax.ShapeDtypeStruct((model.nv,), jnp.float32),
            ).shape[0]
        )
        self.action_size = int(model.nu)
        self.action_low = np.asarray(model.actuator_ctrlrange[:, 0], np.float32)
        self.action_high = np.asarray(model.actuator_ctrlrange[:, 1], np.float32)
        self.max_episode_steps = max_episode_steps
        self.dt = float(model.opt.timestep) * self.spec.frame_skip
        self.model_options = _model_options(model)
        self._init_qpos = np.asarray(model.qpos0, np.float64)
        self._nq, self._nv = int(model.nq), int(model.nv)
        self._body = (
            None
            if self.spec.position_body is None
            else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, self.spec.position_body)
        )
        if self.physics == "c":
            self._engine = _CEngine(model, self, num_threads)
        else:
            self._mjx = import_mjx()
            self._mj_model = model
            self._mjx_model = self._mjx.put_model(
                model, impl="warp" if self.physics == "warp" else "jax"
            )
            if self.physics == "warp":
                self._warp = _WarpBuffers(self._mjx, model, self.warp_batch)

    def __repr__(self) -> str:
        return super().__repr__()[:-1] + f", physics={self.physics!r})"

    # -- reset --------------------------------------------------------------------------

    def initial_qpos_qvel(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Draws gymnasium's reset distribution: ``(qpos, qvel)`` in JAX's float width."""
        qpos_key, qvel_key = jax.random.split(key)
        scale = self.spec.reset_noise_scale
        dtype = float_dtype()
        qpos = self._init_qpos.astype(dtype) + jax.random.uniform(
            qpos_key, (self._nq,), dtype, -scale, scale
        )
        if self.spec.normal_velocity_noise:
            qvel = scale * jax.random.normal(qvel_key, (self._nv,), dtype)
        else:
            qvel = jax.random.uniform(qvel_key, (self._nv,), dtype, -scale, scale)
        return qpos, qvel

    def state_at(self, qpos: jax.Array, qvel: jax.Array) -> tuple[jax.Array, Any]:
        """``(obs, internal)`` of an episode starting at ``qpos``, ``qvel``, as gymnasium's
        ``reset`` leaves it after ``set_state`` (time 0, no solver warm start). On MJX the
        data holds ``qpos`` and ``qvel``; its derived fields are computed by the next step."""
        qpos = jnp.asarray(qpos, float_dtype())
        qvel = jnp.asarray(qvel, float_dtype())
        # The contact forces are 0 at a reset: gymnasium's reset computes none (mj_forward).
        obs = jnp.concatenate(
            [self.spec.observe(jnp, qpos, qvel), jnp.zeros(self._num_contact_forces, qpos.dtype)]
        )
        # A free root body's frame sits at its joint's position: the start x is qpos[0]
        # whichever x the task reads.
        if self.physics == "c":
            internal = CState(bits=self._engine.initial_bits(qpos, qvel))
        else:
            data = self._make_data()
            # No forward pass here: a step starts with one, computed from qpos and qvel
            # alone (the warm start is 0 after a reset), so the data's derived fields would
            # be recomputed before anything reads them. Leaving it out is bit-identical and
            # keeps one copy of the physics out of every program that auto-resets.
            data = data.replace(
                qpos=qpos.astype(data.qpos.dtype), qvel=qvel.astype(data.qvel.dtype)
            )
            internal = MjxState(data=data, x=qpos[0])
        return obs, internal

    def _make_data(self):
        if self.physics == "warp":
            return self._warp.strip(self._warp.template)
        return self._mjx.make_data(self._mjx_model)

    def _reset(self, key):
        return self.state_at(*self.initial_qpos_qvel(key))

    # -- step ---------------------------------------------------------------------------

    def _step(self, internal, action):
        if self.physics == "c":
            # Physics, observation, reward and termination all in float64 on the host.
            bits, obs, reward, terminated = self._engine.step(internal.bits, action)
            return obs, reward, terminated, CState(bits=bits)
        data = internal.data.replace(ctrl=action.astype(internal.data.ctrl.dtype))
        if self.physics == "warp":
            data = self._warp.restore(data)
        data = jax.lax.fori_loop(
            0, self.spec.frame_skip, lambda _, d: self._mjx.step(self._mjx_model, d), data
        )
        if self.spec.reads_contact_forces:  # as gymnasium, after the steps
            data = self._mjx.rne_postconstraint(self._mjx_model, data)
        x_after = data.qpos[0] if self._body is None else data.xpos[self._body, 0]
        dtype = float_dtype()
        step = {
            "qpos": data.qpos.astype(dtype),
            "qvel": data.qvel.astype(dtype),
            "x_before": internal.x.astype(dtype),
            "x_after": x_after.astype(dtype),
            "action": action,
        }
        if self.spec.reads_contact_forces:
            step["contact_forces"] = data.cfrc_ext.reshape(-1).astype(dtype)
        obs, reward, terminated = outcome(
            jnp, self.spec, self.terminate_when_unhealthy, self.dt, step
        )
        if self.physics == "warp":
            # A full buffer dropped contacts: say so, as NaN, never as a quietly wrong step.
            lost = data._impl.overflow != 0
            obs, reward = jnp.where(lost, jnp.nan, obs), jnp.where(lost, jnp.nan, reward)
            data = self._warp.strip(data)
        return obs, reward.astype(dtype), terminated, MjxState(data=data, x=x_after)


def _available_cpus() -> int:
    """CPUs this process may run on (``os.sched_getaffinity`` where the OS has it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


WARP_DEFAULT_BATCH = 1024


def available_physics() -> tuple[str, ...]:
    """``PHYSICS`` less ``"warp"`` where MuJoCo Warp (the optional extra) is not installed."""
    import importlib.util

    warp = all(importlib.util.find_spec(name) for name in ("warp", "mujoco_warp"))
    return PHYSICS if warp else tuple(p for p in PHYSICS if p != "warp")


def _check_warp_batch(name: str, physics: str, warp_batch: Any) -> int | None:
    """The checked ``warp_batch`` (None off Warp), or a ValueError naming the problem; also
    refuses ``"warp"`` where MuJoCo Warp is not installed or the task observes contact
    forces."""
    if physics != "warp":
        if warp_batch is not None:
            raise ValueError(f"{name}: warp_batch is an option of physics='warp' only")
        return None
    if TASKS[name].reads_contact_forces:
        raise ValueError(
            f"{name} observes contact forces, which MJX computes on its JAX implementation "
            "only (rne_postconstraint): physics 'warp' cannot run it; use 'mjx' or 'c'"
        )
    try:
        import mujoco_warp  # noqa: F401
        import warp
    except ImportError:
        raise ValueError(
            f"{name}: physics 'warp' needs MuJoCo Warp, an optional extra: {WARP_EXTRA}"
        ) from None
    warp.config.log_level = 30  # logging.WARNING: no banner, no line per kernel module loaded
    if warp_batch is None:
        return WARP_DEFAULT_BATCH
    if isinstance(warp_batch, bool) or not isinstance(warp_batch, int) or warp_batch < 1:
        raise ValueError(f"{name}: warp_batch must be a positive integer, got {warp_batch!r}")
    return warp_batch


class _WarpBuffers:
    """The buffers MuJoCo Warp shares across a batch (contacts, collision counters), kept out
    of the env state.

    Under ``vmap`` MJX's Warp implementation wants them unbatched (one contact buffer for every
    env stepped together), but a state carried through a grid's nested ``vmap``s comes back
    batched on each axis. Each step refills them from scratch (collision detection resets the
    counters and rewrites the contacts), so the state carries None in their place and a step
    starts from the constant buffers, sized for ``batch`` envs at Warp's own capacity for one.
    """

    def __init__(self, mjx, model, batch: int):
        from mujoco.mjx.warp import types as warp_types

        per_env = int(mjx.make_data(model, impl="warp")._impl.naconmax)
        self.template = mjx.make_data(model, impl="warp", naconmax=batch * per_env)
        batched = warp_types._BATCH_DIM["Data"]
        impl = self.template._impl
        self._shared = {
            field.name: getattr(impl, field.name)
            for field in dataclasses.fields(impl)
            if not batched.get(field.name, True) and hasattr(getattr(impl, field.name), "shape")
        }
        self._empty = dict.fromkeys(self._shared)  # None: no leaf in the carried state

    def strip(self, data):
        return data.replace(_impl=dataclasses.replace(data._impl, **self._empty))

    def restore(self, data):
        return data.replace(_impl=dataclasses.replace(data._impl, **self._shared))


def _check_engine_options(name: str, num_threads: Any, terminate_when_unhealthy: Any) -> None:
    """ValueError naming the option unless ``num_threads`` is None or a positive integer and
    ``terminate_when_unhealthy`` a bool; called before any model is loaded."""
    if num_threads is not None and (
        isinstance(num_threads, bool) or not isinstance(num_threads, int) or num_threads < 1
    ):
        raise ValueError(f"{name}: num_threads must be a positive integer, got {num_threads!r}")
    if not isinstance(terminate_when_unhealthy, bool):
        raise ValueError(
            f"{name}: terminate_when_unhealthy must be True or False, "
            f"got {terminate_when_unhealthy!r}"
        )


def _model_options(model) -> dict[str, Any]:
    """The solver settings in use (for reports and benchmark tables)."""
    opt = model.opt
    return {
        "solver": int(opt.solver),
        "iterations": int(opt.iterations),
        "ls_iterations": int(opt.ls_iterations),
        "timestep": float(opt.timestep),
        "integrator": int(opt.integrator),
    }


class _CEngine:
    """MuJoCo's C engine behind ``jax.pure_callback``: state in, ``frame_skip`` steps, state out.

    Each call steps a whole batch (every env of every cell of a grid: the callback is
    batched with ``vmap_method="broadcast_all"``), split across a thread pool with one
    ``MjData`` per thread.
    """

    def __init__(self, model, task: GymMujocoTask, num_threads: int | None):
        import mujoco

        self._mujoco = mujoco
        self._model = model
        self._task = task  # its spec, time step and termination option
        self._frame_skip = task.spec.frame_skip
        self._body = task._body
        self._spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_WARMSTART)
        self.state_size = int(mujoco.mj_stateSize(model, self._spec))
        # MuJoCo concatenates a state's components in the order of their bits: a component's
        # offset is the size of the components of lower bits.
        self._qpos_at = self._offset(mujoco.mjtState.mjSTATE_QPOS)
        self._qvel_at = self._offset(mujoco.mjtState.mjSTATE_QVEL)
        data = mujoco.MjData(model)
        mujoco.mj_resetData(model, data)
        self._template = np.empty(self.state_size, np.float64)
        mujoco.mj_getState(model, data, self._template, self._spec)
        self._num_threads = num_threads or _available_cpus()
        self._pool = None
        self._datas: list = []
        self._lock = threading.Lock()
        # Programs run from several Python threads may call back at once: one batch at a
        # time, as the thread pool and its MjData are shared.
        self._run_lock = threading.Lock()

    def _offset(self, component) -> int:
        lower = self._spec & (int(component) - 1)
        return int(self._mujoco.mj_stateSize(self._model, lower))

    @property
    def width(self) -> int:
        """uint32 words per env: the state vector and the start x, float64 each."""
        return 2 * (self.state_size + 1)

    # The reset state, built on the host so that it is float64 whatever JAX's width.
    def initial_bits(self, qpos: jax.Array, qvel: jax.Array) -> jax.Array:
        shape = jax.ShapeDtypeStruct((self.width,), jnp.uint32)
        return jax.pure_callback(
            self._initial_bits_host, shape, qpos, qvel, vmap_method="broadcast_all"
        )

    def _initial_bits_host(self, qpos, qvel):
        qpos = np.asarray(qpos, np.float64)
        qvel = np.asarray(qvel, np.float64)
        batch = qpos.shape[:-1]
        state = np.empty((*batch, self.state_size + 1), np.float64)
        state[..., :-1] = self._template
        nq, nv = qpos.shape[-1], qvel.shape[-1]
        state[..., self._qpos_at : self._qpos_at + nq] = qpos
        state[..., self._qvel_at : self._qvel_at + nv] = qvel
        state[..., -1] = qpos[..., 0]
        return state.view(np.uint32)

    def step(self, bits: jax.Array, action: jax.Array):
        """``(bits, obs, reward, terminated)`` after ``frame_skip`` steps; the observation and
        reward come back in JAX's float width, computed in float64."""
        dtype = float_dtype()
        shapes = (
            jax.ShapeDtypeStruct((self.width,), jnp.uint32),
            jax.ShapeDtypeStruct((self._task.observation_size,), dtype),
            jax.ShapeDtypeStruct((), dtype),
            jax.ShapeDtypeStruct((), jnp.bool_),
        )
        host = functools.partial(self._step_host, dtype=np.dtype(dtype))
        return jax.pure_callback(host, shapes, bits, action, vmap_method="broadcast_all")

    def _step_host(self, bits, action, *, dtype):
        bits = np.asarray(bits)
        batch = bits.shape[:-1]
        count = math.prod(batch)
        state = np.ascontiguousarray(bits.reshape(count, self.width)).view(np.float64).copy()
        # The control cost keeps the action's width, as gymnasium's NumPy does with a float32
        # action; MuJoCo's controls are float64.
        action = np.asarray(action).reshape(count, self._model.nu)
        x_before = state[:, -1].copy()
        # Each row's contact forces after its step, for a task that reads them.
        forces = None
        if self._task.spec.reads_contact_forces:
            forces = np.empty((count, 6 * self._model.nbody), np.float64)
        with self._run_lock:
            self._run(state, action.astype(np.float64), forces)
        nq, nv = self._model.nq, self._model.nv
        step = {
            "qpos": state[:, self._qpos_at : self._qpos_at + nq],
            "qvel": state[:, self._qvel_at : self._qvel_at + nv],
            "x_before": x_before,
            "x_after": state[:, -1],
            "action": action,
            "contact_forces": forces,
        }
        task = self._task
        obs, reward, terminated = outcome(
            np, task.spec, task.terminate_when_unhealthy, task.dt, step
        )
        return (
            state.view(np.uint32).reshape(*batch, self.width),
            obs.astype(dtype).reshape(*batch, obs.shape[-1]),
            reward.astype(dtype).reshape(batch),
            terminated.reshape(batch),
        )

    def _run(self, state: np.ndarray, controls: np.ndarray, forces=None) -> None:
        """Steps each row of ``state`` (float64[N, state_size + 1]) in place; with ``forces``
        (float64[N, 6 nbody]), writes each row's contact forces after its step there."""
        count = state.shape[0]
        threads = min(self._num_threads, count)
        if threads <= 1:
            self._run_rows(self._data(0), state, controls, forces, 0, count)
            return
        pool = self._thread_pool(threads)
        bounds = np.linspace(0, count, threads + 1).astype(int)
        futures = [
            pool.submit(
                self._run_rows, self._data(i), state, controls, forces, bounds[i], bounds[i + 1]
            )
            for i in range(threads)
        ]
        for future in futures:
            future.result()

    def _run_rows(self, data, state, controls, forces, start: int, stop: int) -> None:
        mujoco, model, spec = self._mujoco, self._model, self._spec
        for row in range(start, stop):
            mujoco.mj_setState(model, data, state[row, :-1], spec)
            data.ctrl[:] = controls[row]
            mujoco.mj_step(model, data, nstep=self._frame_skip)
            mujoco.mj_getState(model, data, state[row, :-1], spec)
            if forces is not None:  # as gymnasium, after the steps
                mujoco.mj_rnePostConstraint(model, data)
                forces[row] = data.cfrc_ext.reshape(-1)
            state[row, -1] = data.qpos[0] if self._body is None else data.xpos[self._body, 0]

    def _data(self, index: int):
        with self._lock:
            while len(self._datas) <= index:
                self._datas.append(self._mujoco.MjData(self._model))
            return self._datas[index]

    def _thread_pool(self, threads: int) -> ThreadPoolExecutor:
        with self._lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self._num_threads, thread_name_prefix="mujoco")
            return self._pool
