"""flax.linen modules: architecture only (no data, optimiser or learning rate).

Hidden layers use PyTorch's default ``nn.Linear`` weight distribution, U(+-1/sqrt(fan_in)),
with zero biases; every network's output layer starts with those weights scaled by 0.1 and a
zero bias, as the reference code initialises them (``docs/trpo.md``). T-REX's and D-REX's
networks (``ReluMLP``, ``DeterministicPolicy``) keep the CAIL codebase's orthogonal
initialisation instead.
"""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

OUTPUT_SCALE = 0.1


def torch_like_init(scale: float = 1.0):
    """U(-scale / sqrt(fan_in), scale / sqrt(fan_in)): variance scale^2 / (3 fan_in)."""
    return nn.initializers.variance_scaling(scale**2 / 3.0, "fan_in", "uniform")


class MLP(nn.Module):
    """Tanh MLP: ``hidden_sizes`` hidden layers, then a linear output of ``output_size``.

    Input float[..., in]; output float[..., output_size].
    """

    hidden_sizes: Sequence[int]
    output_size: int
    output_bias: bool = True

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for size in self.hidden_sizes:
            x = jnp.tanh(nn.Dense(size, kernel_init=torch_like_init())(x))
        output = nn.Dense(
            self.output_size, kernel_init=torch_like_init(OUTPUT_SCALE), use_bias=self.output_bias
        )
        return output(x)


def orthogonal_init(gain: float = 1.0):
    """Flax's orthogonal initialiser, drawn one matrix at a time under ``vmap``.

    Batched, the draw is a batched LAPACK QR; on a CPU, jaxlib spreads a batched QR over the
    same thread pool that runs the program, and two such QRs running side by side (two layers
    of a grid's networks initialised at once) can wait on each other forever. Drawing each
    matrix in its own loop step (``jax.custom_batching.sequential_vmap``) gives the same
    numbers without the parallel batch.
    """
    base = nn.initializers.orthogonal(gain)

    def init(key: jax.Array, shape, dtype=jnp.float32) -> jax.Array:
        @jax.custom_batching.sequential_vmap
        def draw(key: jax.Array) -> jax.Array:
            return base(key, shape, dtype)

        return draw(key)

    return init


class ReluMLP(nn.Module):
    """ReLU MLP with the CAIL codebase's initialisation (``build_mlp(init=True)``): every
    layer, the output included, has orthogonal weights of gain 1 and zero biases; the output
    is linear.

    Input float[..., in]; output float[..., output_size].
    """

    hidden_sizes: Sequence[int]
    output_size: int
    output_bias: bool = True

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        orthogonal = orthogonal_init(1.0)
        for size in self.hidden_sizes:
            x = nn.relu(nn.Dense(size, kernel_init=orthogonal)(x))
        return nn.Dense(self.output_size, kernel_init=orthogonal, use_bias=self.output_bias)(x)


class DeterministicPolicy(nn.Module):
    """A deterministic policy tanh(ReluMLP(obs)) in [-1, 1] per action dimension (the CAIL
    codebase's ``DeterministicPolicy``; ``pngail_jax.adversarial.bc`` scales it to the action
    bounds).

    Input float[..., obs_size]; output float[..., action_size].
    """

    action_size: int
    hidden_sizes: Sequence[int] = (256, 256, 256)

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return jnp.tanh(ReluMLP(self.hidden_sizes, self.action_size)(obs))


class GaussianPolicy(nn.Module):
    """Diagonal Gaussian policy with a state-independent log standard deviation.

    ``__call__(obs)`` with obs float[..., obs_size] returns ``(mean, log_std)``:
    float[..., action_size] and float[action_size] (initialised to 0).
    """

    action_size: int
    hidden_sizes: Sequence[int] = (100, 100)

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        mean = MLP(self.hidden_sizes, self.action_size)(obs)
        log_std = self.param("log_std", nn.initializers.zeros, (self.action_size,))
        return mean, log_std


class ValueNetwork(nn.Module):
    """State-value MLP: obs float[..., obs_size] -> float[...]."""

    hidden_sizes: Sequence[int] = (100, 100)

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return MLP(self.hidden_sizes, 1)(obs)[..., 0]


def gaussian_log_density(mean: jax.Array, log_std: jax.Array, action: jax.Array) -> jax.Array:
    """log N(action_j; mean_j, exp(log_std_j)^2) of each action dimension: float[..., A]."""
    z = (action - mean) * jnp.exp(-log_std)
    return -0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi)


def gaussian_log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array) -> jax.Array:
    """log N(action; mean, exp(log_std)^2), summed over the last axis: float[...]."""
    return jnp.sum(gaussian_log_density(mean, log_std, action), axis=-1)


def gaussian_kl(
    mean_0: jax.Array, log_std_0: jax.Array, mean_1: jax.Array, log_std_1: jax.Array
) -> jax.Array:
    """KL(N_0 || N_1) of diagonal Gaussians, summed over the last axis: float[...]."""
    variance_ratio = jnp.exp(2 * (log_std_0 - log_std_1))
    mean_term = (mean_0 - mean_1) ** 2 * jnp.exp(-2 * log_std_1)
    return jnp.sum(log_std_1 - log_std_0 + 0.5 * (variance_ratio + mean_term) - 0.5, axis=-1)


def gaussian_entropy(log_std: jax.Array) -> jax.Array:
    """Entropy of a diagonal Gaussian: float[]."""
    return jnp.sum(log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e))


class Discriminator(nn.Module):
    """GAIL discriminator: tanh MLP over [obs, action] giving a logit z (agent = label 1).

    Input float[..., obs_size + action_size]; output float[...]. sigmoid(z) -> 1 on agent data.
    """

    hidden_sizes: Sequence[int] = (100, 100)

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        return MLP(self.hidden_sizes, 1)(x)[..., 0]


def torch_bias_init(fan_in: int):
    """PyTorch's default ``nn.Linear`` bias, U(-1 / sqrt(fan_in), 1 / sqrt(fan_in))."""
    bound = 1.0 / fan_in**0.5

    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    return init


def torch_dense(features: int, x: jax.Array) -> jax.Array:
    """A ``torch.nn.Linear(x.shape[-1], features)`` with its default initialisation (weights
    and bias U(+-1/sqrt(fan_in))), applied to x; call it inside a compact ``__call__``."""
    layer = nn.Dense(
        features, kernel_init=torch_like_init(), bias_init=torch_bias_init(x.shape[-1])
    )
    return layer(x)


class ResidualDiscriminator(nn.Module):
    """f-IRL's state discriminator (``ResNetAIRLDisc`` of twni2016/f-IRL, batch norm off):
    ``Linear(O, hidden_size)`` with no activation after it, ``num_residual_blocks`` blocks
    ``x + tanh(Linear(x))``, then ``Linear(hidden_size, 1)``, clamped to
    ``[-clamp_magnitude, clamp_magnitude]``. PyTorch's default initialisation throughout.

    Input float[..., O] (raw states); output float[...], the logit (demonstration = label 1).
    """

    hidden_size: int = 128
    num_residual_blocks: int = 2
    clamp_magnitude: float = 10.0

    @nn.compact
    def __call__(self, states: jax.Array) -> jax.Array:
        x = torch_dense(self.hidden_size, states)
        for _ in range(self.num_residual_blocks):
            x = x + jnp.tanh(torch_dense(self.hidden_size, x))
        logit = torch_dense(1, x)[..., 0]
        return jnp.clip(logit, -self.clamp_magnitude, self.clamp_magnitude)


class ClampedStateReward(nn.Module):
    """f-IRL's reward r(s) (``MLPReward`` of twni2016/f-IRL, not residual, batch norm off):
    ``Linear(O, h_0)`` with no activation after it, then ``Linear(h_i-1, h_i)`` + ReLU for
    each further size, then ``Linear(h_last, 1)``, clamped to ``[-clamp_magnitude,
    clamp_magnitude]``. With (64, 64): Linear -> Linear -> ReLU -> Linear, one nonlinearity,
    as theirs. PyTorch's default initialisation throughout.

    Input float[..., O] (raw states); output float[...].
    """

    hidden_sizes: Sequence[int] = (64, 64)
    clamp_magnitude: float = 10.0

    @nn.compact
    def __call__(self, states: jax.Array) -> jax.Array:
        x = torch_dense(self.hidden_sizes[0], states)
        for size in self.hidden_sizes[1:]:
            x = jax.nn.relu(torch_dense(size, x))
        reward = torch_dense(1, x)[..., 0]
        return jnp.clip(reward, -self.clamp_magnitude, self.clamp_magnitude)


class LogDensityDiscriminator(nn.Module):
    """DWBC's discriminator (``Discriminator`` of ryanxhr/DWBC): [obs, action] through
    ``Linear(branch_size)`` + ReLU, the policy's per-dimension log-density feature through
    another, the two joined, ``Linear(hidden_size)`` + ReLU, ``Linear(1)``, a sigmoid clipped
    to ``[low, high]`` (the clip also stops the gradient once d saturates, as torch's).
    PyTorch's default initialisation throughout.

    Inputs float[..., O + A] and float[..., A]; output float[...], d in [low, high] (expert
    = 1).
    """

    branch_size: int = 128
    hidden_size: int = 256
    low: float = 0.1
    high: float = 0.9

    @nn.compact
    def __call__(self, inputs: jax.Array, log_density_feature: jax.Array) -> jax.Array:
        pairs = jax.nn.relu(torch_dense(self.branch_size, inputs))
        densities = jax.nn.relu(torch_dense(self.branch_size, log_density_feature))
        x = jax.nn.relu(torch_dense(self.hidden_size, jnp.concatenate([pairs, densities], -1)))
        return jnp.clip(jax.nn.sigmoid(torch_dense(1, x)[..., 0]), self.low, self.high)


class LogitDiscriminator(nn.Module):
    """ISW-BC's discriminator: a ReLU MLP over [obs, action] with a linear logit c (expert =
    label 1), PyTorch's default initialisation (theirs: Keras' he-normal hidden layers).

    Input float[..., O + A]; output float[...].
    """

    hidden_sizes: Sequence[int] = (256, 256)

    @nn.compact
    def __call__(self, inputs: jax.Array) -> jax.Array:
        x = inputs
        for size in self.hidden_sizes:
            x = jax.nn.relu(torch_dense(size, x))
        return torch_dense(1, x)[..., 0]
