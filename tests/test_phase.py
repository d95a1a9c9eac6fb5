"""The phase interface (pngail_jax.adversarial.phase): the order of a PhaseSet's hooks, what it
merges, the keys it hands out, and the trajectories a seed may rank."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.adversarial.phase import (
    InitKeys,
    Phase,
    PhaseContext,
    PhaseSet,
    ranked_trajectories,
)


class Recording(Phase):
    """A phase that records each call and adds its own constant to everything it returns."""

    def __init__(self, name, calls, ranks=False):
        self.names, self.calls, self.ranks_demonstrations = (name,), calls, ranks

    def init(self, context, spec, inputs, confidence, learner_state, keys, ranked):
        self.calls.append(("init", self.names[0], keys, ranked))
        return {f"{self.names[0]}_field": 1}, learner_state + 1

    def reward(self, context, spec, state, transitions, batch, key):
        self.calls.append(("reward", self.names[0]))
        return jnp.full(3, 10.0), {f"{self.names[0]}_new": 2}, {f"{self.names[0]}/m": 3}

    def discriminator_step(self, context, spec, state, batch, key, stepped):
        self.calls.append(("discriminator_step", self.names[0]))
        params, optimizer_state, metrics = stepped
        return (params + 1, optimizer_state, metrics), {}, {}

    def after_update(self, context, spec, before, updated):
        self.calls.append(("after_update", self.names[0]))
        return updated * 2


class Trajectories:
    lengths = jnp.ones(10, jnp.int32)  # ten demonstration trajectories


def context(trajectories=None):
    return PhaseContext(
        env=None, learner=None, discriminator=None, demo_inputs=jnp.zeros((4, 2)),
        action_bounds=(jnp.zeros(1), jnp.ones(1)), num_demos=4, num_envs=1, unroll_length=3,
        trajectories=trajectories,
    )  # fmt: skip


def test_a_phase_set_calls_every_phase_in_order_and_merges_what_they_return():
    calls = []
    phases = PhaseSet(context(), (Recording("a", calls), Recording("b", calls)))
    assert phases.names == ("a", "b") and phases and not PhaseSet(context(), ())
    key = jax.random.key(3)
    fields, learner_state = phases.init(None, None, None, 0, key, 0.2)
    assert fields == {"a_field": 1, "b_field": 1} and learner_state == 2
    # One split of fold_in(key, 1) for every phase: each sees the same keys.
    expected = InitKeys.split(jax.random.fold_in(key, 1))
    for call in calls:
        assert all(
            np.array_equal(jax.random.key_data(a), jax.random.key_data(b))
            for a, b in zip(call[2], expected, strict=True)
        )
        assert call[3] is None  # no phase ranks demonstrations
    rewards, fields, metrics = phases.reward(None, None, None, None, jnp.ones(3), key)
    np.testing.assert_array_equal(rewards, 21.0)  # the adversarial 1 plus both terms
    assert fields == {"a_new": 2, "b_new": 2} and metrics == {"a/m": 3, "b/m": 3}
    stepped, _, _ = phases.discriminator_step(None, None, None, key, (0, "adam", {}))
    assert stepped == (2, "adam", {})
    assert phases.after_update(None, None, 1) == 4
    assert [c[:2] for c in calls[2:]] == [
        ("reward", "a"), ("reward", "b"), ("discriminator_step", "a"),
        ("discriminator_step", "b"), ("after_update", "a"), ("after_update", "b"),
    ]  # fmt: skip
    assert phases.get(Recording) is phases.phases[0] and phases.get(PhaseSet) is None


def test_the_ranked_trajectories_are_drawn_only_for_a_phase_that_ranks():
    calls = []
    key = jax.random.key(0)
    ranking = PhaseSet(context(Trajectories()), (Recording("r", calls, ranks=True),))
    fields, _ = ranking.init(None, None, None, 0, key, 0.3)
    expected = ranked_trajectories(10, 0.3, jax.random.fold_in(key, 2))
    np.testing.assert_array_equal(fields["ranked_trajectories"], expected)
    np.testing.assert_array_equal(calls[0][3], expected)
    plain = PhaseSet(context(Trajectories()), (Recording("p", []),))
    assert "ranked_trajectories" not in plain.init(None, None, None, 0, key, 0.3)[0]


@pytest.mark.parametrize(("ratio", "expected"), [(0.3, 3), (0.05, 2), (0.0, 2), (1.0, 10)])
def test_a_share_of_the_trajectories_is_ranked_at_least_two(ratio, expected):
    """round(ratio * K), at least 2, of K = 10 trajectories; each seed draws its own."""
    draws = [np.asarray(ranked_trajectories(10, ratio, jax.random.key(seed))) for seed in range(8)]
    assert all(draw.dtype == bool and draw.sum() == expected for draw in draws)
    if 2 <= expected < 10:
        assert len({draw.tobytes() for draw in draws}) > 1
