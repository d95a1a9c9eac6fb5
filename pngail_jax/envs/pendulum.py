"""Pendulum-v1 in pure JAX, equal to gymnasium's ``Pendulum-v1`` (gymnasium 1.x).

Same reset distribution (theta ~ U(-pi, pi), theta_dot ~ U(-1, 1)), same order of operations
(clip the torque to [-2, 2]; the reward is computed from the pre-step state and the clipped
torque; integrate theta_dot, clip it to [-8, 8], then integrate theta with the new theta_dot),
observation ``[cos theta, sin theta, theta_dot]`` and a 200-step time limit. It computes in
the float width JAX is set to (float32 by default, float64 under ``jax_enable_x64``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.envs.base import Env, check_positive_finite, check_positive_int, float_dtype


@struct.dataclass
class PendulumInternal:
    theta: jax.Array  # float[], angle in radians, 0 = upright, not wrapped
    theta_dot: jax.Array  # float[], angular velocity in rad/s


class Pendulum(Env):
    """gymnasium's Pendulum-v1. Options: ``g`` (gravity, default 10.0; finite and > 0) and
    ``max_episode_steps`` (a positive integer, default 200)."""

    max_speed = 8.0
    max_torque = 2.0
    dt = 0.05
    mass = 1.0
    length = 1.0

    def __init__(self, g: float = 10.0, max_episode_steps: int = 200):
        self.name = "Pendulum-v1"
        self.g = check_positive_finite(self.name, "g", g)
        self.max_episode_steps = check_positive_int(
            self.name, "max_episode_steps", max_episode_steps
        )
        self.observation_size = 3
        self.action_size = 1
        self.action_low = np.full((1,), -self.max_torque, np.float32)
        self.action_high = np.full((1,), self.max_torque, np.float32)

    def _reset(self, key):
        dtype = float_dtype()
        high = jnp.array([jnp.pi, 1.0], dtype)
        theta, theta_dot = jax.random.uniform(key, (2,), dtype, minval=-high, maxval=high)
        internal = PendulumInternal(theta=theta, theta_dot=theta_dot)
        return _observe(internal), internal

    def _step(self, internal, action):
        theta, theta_dot = internal.theta, internal.theta_dot
        torque = jnp.clip(action[0], -self.max_torque, self.max_torque)
        cost = _angle_normalize(theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * torque**2
        acceleration = (
            3 * self.g / (2 * self.length) * jnp.sin(theta)
            + 3.0 / (self.mass * self.length**2) * torque
        )
        new_theta_dot = jnp.clip(
            theta_dot + acceleration * self.dt, -self.max_speed, self.max_speed
        )
        new_theta = theta + new_theta_dot * self.dt
        new_internal = PendulumInternal(theta=new_theta, theta_dot=new_theta_dot)
        return _observe(new_internal), -cost, False, new_internal


def _angle_normalize(theta):
    return ((theta + jnp.pi) % (2 * jnp.pi)) - jnp.pi


def _observe(internal: PendulumInternal) -> jax.Array:
    theta = internal.theta
    return jnp.stack([jnp.cos(theta), jnp.sin(theta), internal.theta_dot])
