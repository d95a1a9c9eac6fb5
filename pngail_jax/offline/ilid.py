"""ILID's parts of the offline trainer (Yue et al., ICML 2024; docs/methods.md, "ILID"): its
two discriminators, trained before the policy's first step, the selection of the other rows
whose next K states reach an expert-like state, and the union its weighted term draws from.

The union comes two ways (``ILID_UNIONS``, ``OfflineConfig.ilid_union``):

- ``"intended"`` (the default): E and the selected rows S, the two buffers' union that the
  released code's comment names (main.py:757, "distinguish replay_buffer_e and
  replay_buffer_u");
- ``"released"``: as the released code samples it (HansenHua/ILID-offline-imitation-learning
  @ eca999b, main.py). Its union buffer is a ``ReplayBuffer`` (755), whose ``__init__``
  allocates ``max_size`` = 1,000,000 zero rows (231, 238-245); ``add_transitions`` concatenates
  E, then S, onto them and sets ``size`` to the whole array's length (282-291; 756, 772), and
  ``sample`` draws uniformly from ``range(size)`` (247-248). So each draw of the state-action
  discriminator's negatives (``train_disc``, 614-631) and of the policy loss's weighted term
  (480, 507-511) is a zero row (normalised state 0, action 0) with probability
  ``1e6 / (1e6 + |E| + |S|)`` (``released_zero_share``). We draw each union row as a zero row
  with that probability instead of allocating the rows; a zero row's weight is d / (1 - d) of
  the state-action discriminator at the zero input.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from pngail_jax.config.validation import fail, is_among
from pngail_jax.fitting import adam_step, squared_norm
from pngail_jax.networks import LogitDiscriminator
from pngail_jax.offline.losses import clipped_probability, ilid_discriminator_loss, ilid_selection

ILID_UNIONS = ("intended", "released")
# The released code's union buffer: ReplayBuffer's max_size zero rows (main.py:231), before E
# and S are concatenated onto them.
RELEASED_UNION_PADDING = 1_000_000
# How many times each discriminator's training reports its steps to ``IlidSelection.progress``.
PROGRESS_REPORTS = 100


def check_union(union: str, name: str = "ilid_union") -> None:
    """ConfigError (a ValueError) naming the field ``ilid_union`` (called ``name``) unless
    ``union`` is one of ``ILID_UNIONS``."""
    if not is_among(union, ILID_UNIONS):
        fail("ilid_union", f"must be one of {', '.join(ILID_UNIONS)}, got {union!r}", name=name)


def uniform_over(mask: jax.Array) -> jax.Array:
    """float[M]: probabilities uniform over ``mask``'s rows (over every row if it has none)."""
    count = mask.sum()
    return jnp.where(count > 0, mask / jnp.maximum(count, 1), 1.0 / mask.shape[0])


def released_zero_share(num_union_rows: jax.Array) -> jax.Array:
    """float[]: the share of the released code's union draws that are zero rows, for a union
    of ``num_union_rows`` real rows (|E| + |S|): 1e6 / (1e6 + n). At our split sizes (at
    most a few thousand rows) it is above 0.997."""
    padding = jnp.float32(RELEASED_UNION_PADDING)
    return padding / (padding + jnp.asarray(num_union_rows, jnp.float32))


def with_zero_rows(key: jax.Array, rows: jax.Array, zero_share: jax.Array):
    """The released code's draw from its padded union: each of ``rows`` float[B, D] (drawn
    from E and S) replaced by a zero row with probability ``zero_share`` float[]; returns the
    rows and bool[B], which were."""
    zero = jax.random.bernoulli(key, zero_share, rows.shape[:1])
    return jnp.where(zero[:, None], jnp.zeros_like(rows), rows), zero


def odds(d: jax.Array) -> jax.Array:
    """ILID's weight d / (1 - d) of a clipped discriminator output d in [0.1, 0.9]: in
    [1/9, 9], no gradient. float[...]."""
    return jax.lax.stop_gradient(d / (1 - d))


class IlidSelection:
    """ILID's discriminators and selection, as its codebase runs them before the policy
    learns. Static: the discriminators' hidden sizes, their Adam steps, the batch size (each
    side), the union's kind (``ILID_UNIONS``). ``select`` runs both phases. ``progress``: None,
    or a host function the compiled training calls (``jax.debug.callback``, once for every
    cell of a grid) with the steps done of both discriminators, ``PROGRESS_REPORTS`` times
    each; set it before the program is compiled. The numbers are the same either way."""

    def __init__(self, hidden_sizes, discriminator_steps: int, batch_size: int,
                 union: str = "intended"):  # fmt: skip
        check_union(union)
        self.network = LogitDiscriminator(hidden_sizes)  # on states, or on (s, a)
        self.discriminator_steps = discriminator_steps
        self.batch_size, self.union = batch_size, union
        self.optimizer = optax.scale_by_adam()
        self.progress = None

    def select(self, spec, rows, observations, successors, expert, true_confidence, key):
        """ILID's two phases: a state discriminator of the expert rows' states against the
        other rows' states; the other rows whose next K states include one it puts at or
        above ``spec.ilid_bar`` (S); a state-action discriminator of the expert rows against
        the union (E and S, padded with zero rows when ``union`` is ``"released"``), whose
        d / (1 - d) weights the policy's BC on the union.

        ``spec``: an ``OfflineSpec`` (its ``ilid_*`` fields); ``rows`` float[M, O + A]: the
        split's rows, observations normalised; ``observations`` float[N, O]: every row's
        state of the file, normalised (what ``successors`` int[M, K] index, -1 past a
        trajectory's end); ``expert`` bool[M]; ``true_confidence`` float[M], read only by the
        metrics. Returns (the trainer state's ILID fields, the selection's metrics, the two
        discriminators' parameters ``{"state", "pair"}``)."""
        size = observations.shape[-1]
        state_key, pair_key = jax.random.split(key)
        other = ~expert
        state_params, state_loss = self.discriminator(
            spec, rows[:, :size], expert, other, state_key, phase=0
        )
        d_states = clipped_probability(self.network.apply(state_params, observations))
        selected = other & ilid_selection(d_states >= spec.ilid_bar, successors)
        union = expert | selected
        released = self.union == "released"
        zero_share = released_zero_share(union.sum()) if released else None
        pair_params, pair_loss = self.discriminator(
            spec, rows, expert, union, pair_key, zero_share, phase=1
        )
        fields = {  # nothing selected: the selected-rows term clones the expert rows instead
            "ilid_selected_probability": jnp.where(
                selected.any(), uniform_over(selected), uniform_over(expert)
            ),
            "ilid_union_probability": uniform_over(union),
            "ilid_weight": odds(clipped_probability(self.network.apply(pair_params, rows))),
        }
        metrics = _selection_metrics(selected, other, true_confidence)
        metrics |= {"ilid/state_disc_loss": state_loss, "ilid/pair_disc_loss": pair_loss}
        if released:
            zero_input = jnp.zeros(rows.shape[-1], rows.dtype)
            zero_weight = odds(clipped_probability(self.network.apply(pair_params, zero_input)))
            fields |= {"ilid_zero_share": zero_share, "ilid_zero_weight": zero_weight}
            metrics["ilid/union_zero_share"] = zero_share
        return fields, metrics, {"state": state_params, "pair": pair_params}

    def discriminator(self, spec, rows, positive, negative, key, zero_share=None, phase=0):
        """An ILID discriminator on ``rows`` float[M, D] (normalised states, or states and
        actions), trained ``discriminator_steps`` Adam steps with coupled weight decay on
        batches drawn from the ``positive`` and ``negative`` rows (bool[M]), each negative a
        zero row with probability ``zero_share`` float[] where given (the released code's
        padded union); its parameters and its last loss. ``phase``: 0 for the state
        discriminator, 1 for the state-action one (where its steps count in ``progress``)."""
        init_key, loop_key = jax.random.split(key)
        params = self.network.init(init_key, rows[0])
        optimizer_state = self.optimizer.init(params)
        p_positive, p_negative = uniform_over(positive), uniform_over(negative)
        batch = self.batch_size

        def step(index, carry):
            params, optimizer_state, _ = carry
            positive_key, negative_key = jax.random.split(jax.random.fold_in(loop_key, index))
            pos = rows[jax.random.choice(positive_key, rows.shape[0], (batch,), p=p_positive)]
            neg = rows[jax.random.choice(negative_key, rows.shape[0], (batch,), p=p_negative)]
            if zero_share is not None:
                neg, _ = with_zero_rows(jax.random.fold_in(negative_key, 1), neg, zero_share)

            def loss_fn(params):
                d_pos = clipped_probability(self.network.apply(params, pos))
                d_neg = clipped_probability(self.network.apply(params, neg))
                loss, _ = ilid_discriminator_loss(d_pos, d_neg)
                return loss + 0.5 * spec.ilid_discriminator_weight_decay * squared_norm(params)

            loss, grads = jax.value_and_grad(loss_fn)(params)
            params, optimizer_state = adam_step(
                params, optimizer_state, grads, spec.ilid_discriminator_learning_rate
            )
            return params, optimizer_state, loss

        carry = (params, optimizer_state, jnp.zeros((), jnp.float32))
        params, _, loss = self._reporting_loop(step, carry, phase)
        return params, loss

    def _reporting_loop(self, step, carry, phase: int):
        """``step`` (index, carry) -> carry run for indices 0 .. ``discriminator_steps`` - 1,
        in ``PROGRESS_REPORTS`` blocks (and what is left), ``progress`` told after each block
        when set: the same steps on the same indices as one loop."""
        steps = self.discriminator_steps
        every = max(1, steps // PROGRESS_REPORTS)
        blocks = steps // every

        def block(index, carry):
            carry = jax.lax.fori_loop(index * every, (index + 1) * every, step, carry)
            if self.progress is not None:
                jax.debug.callback(self.progress, phase * steps + (index + 1) * every)
            return carry

        carry = jax.lax.fori_loop(0, blocks, block, carry)
        return jax.lax.fori_loop(blocks * every, steps, step, carry)


def _selection_metrics(selected, other, true_confidence) -> dict[str, jax.Array]:
    """``ilid/num_selected`` of ``ilid/num_other``, and ``ilid/selected_true_confidence``
    against ``ilid/other_true_confidence``: how good the selected rows are, by the
    confidences nobody read, against those it chose from (bool[M], bool[M], float[M])."""
    num_selected, num_other = selected.sum(), other.sum()
    return {
        "ilid/num_selected": num_selected.astype(jnp.float32),
        "ilid/selected_true_confidence": jnp.sum(jnp.where(selected, true_confidence, 0))
        / jnp.maximum(num_selected, 1),
        "ilid/num_other": num_other.astype(jnp.float32),  # what it selected from
        "ilid/other_true_confidence": jnp.sum(jnp.where(other, true_confidence, 0))
        / jnp.maximum(num_other, 1),
    }
