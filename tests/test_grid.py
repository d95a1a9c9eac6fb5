"""The adversarial train function and grids: vmap, sharding, chunking, resume, NaN isolation.

Small configs throughout (Pendulum, 4 envs x 50 steps, a 50-step classifier). Tolerances:
the same compiled program run twice (repeat, resume) is bit-identical; two programs XLA
compiles differently (vmapped vs single, sharded vs not, chunked vs whole, several
processes vs one, other constants) agree to ``CROSS_PROGRAM_RTOL``, as the float error of
each metric allows: XLA may order float32 reductions differently in each program, and
differently on each machine.
"""

import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.methods import method_spec
from pngail_jax.adversarial.trainer import (
    AdversarialConfig,
    AdversarialHyperparams,
    AdversarialTrainer,
)
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import DemonstrationError, Demonstrations
from pngail_jax.grid import Grid, make_cells, nonfinite_cells, stack_cells
from pngail_jax.rl import LearnerConfig, RolloutConfig, TRPOConfig
from pngail_jax.storage.checkpoint import restore_tree, save_tree

COMPARED = ("eval/return", "disc/loss", "disc/acc_agent", "train/reward", "trpo/kl")

# Worst relative differences measured between two programs on an Intel Xeon, with its
# default and with SSE4.2-only code: eval/return 1.2e-5 (1.2e-5 on an AMD EPYC), trpo/kl
# 5e-5, the others 1e-7 or less.
CROSS_PROGRAM_RTOL = {
    # Pendulum's dynamics amplify last-bit differences of the policy over 200 steps.
    "eval/return": 1e-3,
    # A KL near max_kl = 0.01 is a small difference of O(1) terms after a conjugate-gradient
    # solve: its float error is relative to those terms, 100 times its own size.
    "trpo/kl": 1e-3,
    # Means over one batch of networks' outputs: a few float32 ulps.
    "disc/loss": 1e-4,
    "disc/acc_agent": 1e-4,
    "train/reward": 1e-4,
}


def assert_close_across_programs(actual, expected, name):
    np.testing.assert_allclose(
        actual, expected, rtol=CROSS_PROGRAM_RTOL[name], atol=1e-6, err_msg=name
    )


def small_setup(num_iterations=2, eval_every=1, **config_overrides):
    env = envs.make("Pendulum-v1")
    rng = np.random.default_rng(0)
    num_rows = 120
    demos = Demonstrations(
        observations=rng.normal(size=(num_rows, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(num_rows, 1)).astype(np.float32),
        confidence=np.repeat(rng.uniform(0.2, 1.0, 6), 20).astype(np.float32),
        metadata={"random_return": -1200.0, "optimal_return": -150.0},
    )
    config = AdversarialConfig(
        rollout=RolloutConfig(
            num_envs=4,
            unroll_length=50,
            num_iterations=num_iterations,
            eval_every=eval_every,
            num_eval_episodes=2,
        ),
        learner=LearnerConfig(trpo=TRPOConfig(num_value_minibatches=5)),
        classifier=ClassifierConfig(num_steps=50),
        **config_overrides,
    )
    return env, demos, config


def small_grid_inputs(methods=("gail", "pngail", "wgail"), num_seeds=2):
    cells = make_cells(methods, num_seeds)
    return cells, stack_cells(cells, jax.random.key(0), family=ADVERSARIAL)


def run_single_and_grid() -> dict:
    """3 methods x 2 seeds as one vmapped program and as six separate runs."""
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    cells, (hyperparams, specs, keys) = small_grid_inputs()
    _, grid_metrics = jax.jit(jax.vmap(trainer.train))(hyperparams, specs, keys)
    single = jax.jit(trainer.train)
    rows = []
    for index in range(len(cells)):
        pick = jax.tree.map(lambda x, i=index: x[i], (hyperparams, specs, keys))
        rows.append(single(*pick)[1])
    return {
        name: [
            np.asarray(grid_metrics[name]).tolist(),
            [np.asarray(r[name]).tolist() for r in rows],
        ]
        for name in COMPARED
    }


@pytest.mark.slow
def test_grid_matches_runs_one_at_a_time():
    results = run_single_and_grid()
    for name, (grid_values, single_values) in results.items():
        assert_close_across_programs(grid_values, single_values, name)


def chunked_grid_results(devices=None, chunks=2):
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    _, inputs = small_grid_inputs()
    grid = Grid(trainer, inputs, blocks_per_chunk=1, devices=devices)
    state, _ = grid.init()
    outputs = []
    for _ in range(chunks):
        state, metrics = grid.run_chunk(state)
        outputs.append(grid.fetch(metrics))
    return grid, state, {name: np.concatenate([o[name] for o in outputs], 1) for name in COMPARED}


def sharded_vs_unsharded() -> dict:
    devices = jax.devices()
    assert len(devices) == 4, devices
    sharded_grid, _, sharded = chunked_grid_results(devices)
    _, _, unsharded = chunked_grid_results(devices[:1])
    return {
        "num_padded": sharded_grid.num_padded,
        **{name: [sharded[name].tolist(), unsharded[name].tolist()] for name in COMPARED},
    }


@pytest.mark.heavy
@pytest.mark.slow
def test_sharded_over_four_devices_matches_one_device():
    from conftest import run_in_subprocess

    results = run_in_subprocess(
        __file__,
        "sharded_vs_unsharded",
        {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"},
    )
    assert results.pop("num_padded") == 8  # 6 cells padded to a multiple of 4 devices
    for name, (sharded, unsharded) in results.items():
        assert_close_across_programs(sharded, unsharded, name)


def grid_metrics_bytes() -> dict:
    """The 6-cell grid's metrics (2 iterations), as hexadecimal bytes per metric."""
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    _, inputs = small_grid_inputs()
    _, metrics = jax.device_get(jax.jit(jax.vmap(trainer.train))(*inputs))
    return {name: np.ascontiguousarray(metrics[name]).tobytes().hex() for name in COMPARED}


@pytest.mark.slow
@pytest.mark.heavy
@pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
    reason="needs a second CPU to run on",
)
def test_the_number_of_cores_does_not_change_a_single_bit():
    """What docs/sweep.md promises for reproducibility: the same program on the same machine
    gives the same bits, whatever the number of cores it runs on (XLA's CPU thread pools are
    sized by the process's CPUs). A fresh Python on one CPU, compiling the 6-cell grid itself
    (the persistent cache off), against this process's run of it on every CPU it has."""
    from conftest import run_in_subprocess

    one_core = run_in_subprocess(
        __file__,
        "grid_metrics_bytes",
        {"JAX_ENABLE_COMPILATION_CACHE": "false"},
        cpus={min(os.sched_getaffinity(0))},
    )
    assert one_core == grid_metrics_bytes()


@pytest.mark.slow
def test_chunks_match_the_whole_scan_and_repeat_bit_identically():
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    _, inputs = small_grid_inputs()
    _, whole = jax.jit(jax.vmap(trainer.train))(*inputs)
    _, _, first = chunked_grid_results()
    _, _, second = chunked_grid_results()
    for name in COMPARED:
        # Chunked and whole are different programs; the chunked one repeated is the same.
        assert_close_across_programs(first[name], whole[name], name)
        np.testing.assert_array_equal(first[name], second[name], err_msg=name)


@pytest.mark.slow
def test_resume_from_a_checkpoint_is_bit_exact(tmp_path):
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    _, inputs = small_grid_inputs()
    assert_resumes_bit_exactly(trainer, inputs, tmp_path)


def assert_resumes_bit_exactly(trainer, inputs, tmp_path):
    """One chunk, a checkpoint, then the next chunk both uninterrupted and from the restored
    checkpoint: every metric bit-identical."""
    grid = Grid(trainer, inputs, blocks_per_chunk=1)
    state, _ = grid.init()
    state, _ = grid.run_chunk(state)
    template = jax.eval_shape(lambda: grid.unpad(state))
    save_tree(tmp_path / "state", grid.unpad(state))
    _, uninterrupted = grid.run_chunk(state)
    restored = grid.place(restore_tree(tmp_path / "state", template))
    _, resumed = grid.run_chunk(restored)
    for name in uninterrupted:
        np.testing.assert_array_equal(resumed[name], uninterrupted[name], err_msg=name)


@pytest.mark.slow
def test_a_nan_cell_is_reported_and_leaves_the_others_alone():
    """One cell's discriminator learning rate poisoned with NaN: that cell is reported, and the
    five others are bit-identical to the clean grid's (the 6-cell grid of
    ``test_grid_matches_runs_one_at_a_time``: the same program, so compiled once)."""
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    cells, (hyperparams, specs, keys) = small_grid_inputs()
    poisoned = hyperparams.replace(
        discriminator_learning_rate=hyperparams.discriminator_learning_rate.at[1].set(jnp.nan)
    )
    train = jax.jit(jax.vmap(trainer.train))
    _, clean = train(hyperparams, specs, keys)
    _, mixed = train(poisoned, specs, keys)
    mixed = jax.device_get(mixed)
    assert nonfinite_cells(mixed, config.rollout.eval_every).tolist() == [1]
    assert nonfinite_cells(jax.device_get(clean), config.rollout.eval_every).tolist() == []
    np.testing.assert_array_equal(clean["rollout/nonfinite_actions"], 0)  # the count is there
    others = [index for index in range(len(cells)) if index != 1]
    for name in COMPARED:
        np.testing.assert_array_equal(
            mixed[name][others], np.asarray(clean[name])[others], err_msg=name
        )


def test_wgail_weights_refresh_on_schedule():
    env, demos, config = small_setup(
        num_iterations=3, eval_every=1, wgail_refresh_every=2, wgail_refresh_until=2
    )
    trainer = AdversarialTrainer(config, env, demos)
    hyperparams, spec, key = (
        AdversarialHyperparams.create(),
        method_spec("wgail"),
        jax.random.key(1),
    )
    state, _ = jax.jit(trainer.init)(hyperparams, spec, key)
    run = jax.jit(functools.partial(trainer.run_blocks, num_blocks=1))
    state, _ = run(hyperparams, spec, state)
    state, _ = run(hyperparams, spec, state)
    np.testing.assert_array_equal(state.importance_weights, 1.0)  # before iteration 2: w = 1
    before = state
    state, _ = run(hyperparams, spec, state)  # iteration 2 refreshes from `before`
    inputs = demos.inputs[np.asarray(before.demo_rows)]
    logits = train_discriminator_logits(trainer, before, inputs)
    log_pi = trainer.learner.log_prob(before.learner, inputs[:, :3], inputs[:, 3:])
    expected = np.sqrt(np.exp(-np.asarray(logits, np.float64)) * np.exp(np.asarray(log_pi)))
    np.testing.assert_allclose(state.importance_weights, expected, rtol=1e-4)
    refreshed = state.importance_weights
    state, _ = run(hyperparams, spec, state)  # iteration 3 > wgail_refresh_until: kept
    np.testing.assert_array_equal(state.importance_weights, refreshed)


def test_policy_reward_comes_from_the_discriminator_before_its_step():
    from pngail_jax.adversarial.losses import policy_reward

    env, demos, config = small_setup(num_iterations=1)
    trainer = AdversarialTrainer(config, env, demos)
    hyperparams, spec = AdversarialHyperparams.create(), method_spec("pngail")
    state, _ = jax.jit(trainer.init)(hyperparams, spec, jax.random.key(2))
    _, transitions = jax.jit(trainer.learner.rollout)(state.learner)  # the iteration's own rollout
    clipped = np.clip(transitions.action, env.action_low, env.action_high)
    agent_inputs = np.concatenate([transitions.obs, clipped], axis=-1)
    run = jax.jit(functools.partial(trainer.run_blocks, num_blocks=1))
    new_state, metrics = run(hyperparams, spec, state)

    def mean_reward(params):
        return float(
            np.mean(policy_reward(train_discriminator_logits(trainer, params, agent_inputs)))
        )

    # The block's program against an eager apply on another batch shape: float32 sums in
    # another order (1e-7 seen); the step moves the mean by 5e-3.
    np.testing.assert_allclose(metrics["train/reward"][0], mean_reward(state), rtol=1e-4)
    assert abs(mean_reward(new_state) - mean_reward(state)) > 1e-4  # the step moved it


def train_discriminator_logits(trainer, state, inputs):
    from pngail_jax.networks import Discriminator

    model = Discriminator(trainer.config.discriminator_hidden_sizes)
    return model.apply(state.discriminator_params, inputs)


def test_given_confidences_need_no_classifier_and_classifier_fills_unlabelled_rows():
    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    hyperparams, key = AdversarialHyperparams.create(label_ratio=0.25), jax.random.key(3)
    given, _ = jax.jit(trainer.init)(hyperparams, method_spec("icgail"), key)
    classified, errors = jax.jit(trainer.init)(hyperparams, method_spec("pngail"), key)
    labelled = np.asarray(given.labelled)
    assert labelled.sum() == 30  # round(0.25 * 120)
    np.testing.assert_array_equal(given.demo_rows, classified.demo_rows)  # same seed, same split
    np.testing.assert_array_equal(given.confidence[labelled], classified.confidence[labelled])
    # An in-program mean against NumPy's: float32 sums of 30 terms in another order.
    np.testing.assert_allclose(
        given.confidence[~labelled], np.mean(np.asarray(given.confidence)[labelled]), rtol=1e-5
    )
    assert not np.allclose(classified.confidence[~labelled], given.confidence[~labelled])
    assert 0 <= float(errors["confidence/mae"]) <= 1
    # 2IWIL's mean(r) is over the whole split, not a batch (rtol: 120 terms, as above).
    np.testing.assert_allclose(
        classified.stats.mean_confidence, np.mean(classified.confidence), rtol=1e-5
    )


@pytest.mark.slow
def test_methods_that_read_no_confidences_run_without_them():
    """GAIL without confidences is GAIL with any: the same numbers up to the float error
    between two programs; PN-GAIL is refused."""
    env, demos, config = small_setup()
    with_confidence = AdversarialTrainer(config, env, demos)
    without = AdversarialTrainer(config, env, Demonstrations(demos.observations, demos.actions))
    args = (AdversarialHyperparams.create(), method_spec("gail"), jax.random.key(5))
    _, expected = jax.jit(with_confidence.train)(*args)
    _, metrics = jax.jit(without.train)(*args)
    for name in COMPARED:
        # Two trainers, so two programs (their demonstration constants differ); equal here.
        assert_close_across_programs(metrics[name], expected[name], name)
    assert np.isnan(metrics["confidence/mae"])  # no confidences: no error to report
    without.check_methods(["gail", "wgail"])
    with pytest.raises(DemonstrationError, match="no confidences, which pngail, 2iwil read"):
        without.check_methods(["gail", "pngail", "2iwil"])


def test_bad_demonstrations_are_clear_errors():
    env, demos, config = small_setup()
    with pytest.raises(DemonstrationError, match="only 120 rows"):
        AdversarialTrainer(AdversarialConfig(rollout=config.rollout, num_demos=500), env, demos)
    wrong_size = Demonstrations(demos.observations[:, :2], demos.actions, demos.confidence)
    with pytest.raises(DemonstrationError, match="observations of size 2"):
        AdversarialTrainer(config, env, wrong_size)
    with pytest.raises(ValueError, match="label_ratio"):
        AdversarialHyperparams.create(label_ratio=1.0)


def multihost_worker(process_id: int, port: int) -> dict:
    """One of two processes of a multi-host grid (jax.distributed over CPU, gloo)."""
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(f"localhost:{port}", num_processes=2, process_id=process_id)
    assert jax.process_count() == 2 and len(jax.devices()) == 2
    grid, state, metrics = chunked_grid_results(chunks=2)
    assert not grid.sharding.is_fully_addressable  # the mesh spans both processes
    state_returns = grid.fetch(state).learner.env_steps
    return {name: np.asarray(metrics[name]).tolist() for name in COMPARED} | {
        "env_steps": np.asarray(state_returns).tolist()
    }


@pytest.mark.heavy
@pytest.mark.slow
def test_two_processes_match_one():
    import json
    import os
    import socket
    import subprocess
    import sys

    def attempt() -> tuple[list, str]:
        """Both processes on a port free a moment ago ((results, "") or ([], their stderr)):
        another program may take it before the coordinator binds it, so a failed start is
        tried again on a new port."""
        with socket.socket() as probe:
            probe.bind(("localhost", 0))
            port = probe.getsockname()[1]
        code = (
            "import json, runpy, sys\n"
            f"namespace = runpy.run_path({__file__!r})\n"
            f"result = namespace['multihost_worker'](int(sys.argv[1]), {port})\n"
            "print('RESULT ' + json.dumps(result))\n"
        )
        env = {**os.environ, "PYTHONPATH": os.getcwd()}
        processes = [
            subprocess.Popen(
                [sys.executable, "-c", code, str(i)],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for i in range(2)
        ]
        outputs = [process.communicate(timeout=600) for process in processes]
        results, errors = [], ""
        for process, (stdout, stderr) in zip(processes, outputs, strict=True):
            lines = [line for line in stdout.splitlines() if line.startswith("RESULT ")]
            if process.returncode != 0 or not lines:
                return [], errors + stderr[-3000:]
            results.append(json.loads(lines[-1].removeprefix("RESULT ")))
        return results, ""

    for _ in range(3):
        results, errors = attempt()
        if results:
            break
    assert results, errors
    assert results[0] == results[1]  # both processes see the whole gathered grid
    _, _, single = chunked_grid_results(chunks=2)
    for name in COMPARED:
        assert_close_across_programs(results[0][name], single[name], name)
    assert results[0]["env_steps"] == [2 * 200] * 6


def test_a_grid_over_further_axes_equals_its_cells_run_alone():
    """Axes over a TRPO hyperparameter and a loss coefficient (3 x 2 settings, one program: the
    6-cell grid's of ``test_grid_matches_runs_one_at_a_time``, so compiled once): each cell's
    inputs are its values set by hand, and its metrics those of the cell alone."""
    from pngail_jax.adversarial.trainer import AdversarialHyperparams

    env, demos, config = small_setup()
    trainer = AdversarialTrainer(config, env, demos)
    axes = (("max_kl", (0.005, 0.01, 0.02)), ("importance_weighted_coef", (0.0, 1.0)))
    cells = make_cells(["pngail"], 1, axes=axes)
    assert [dict(cell.axes) for cell in cells] == [
        {"max_kl": kl, "importance_weighted_coef": w}
        for kl in (0.005, 0.01, 0.02)
        for w in (0.0, 1.0)
    ]
    assert cells[1].setting == "label_ratio=0.2,noise=0,max_kl=0.005,importance_weighted_coef=1"
    inputs = stack_cells(cells, jax.random.key(0), family=ADVERSARIAL)
    _, grid_metrics = jax.jit(jax.vmap(trainer.train))(*inputs)
    single = jax.jit(trainer.train)
    for index, cell in enumerate(cells):
        values = dict(cell.axes)
        by_hand = (
            AdversarialHyperparams.create(max_kl=values["max_kl"]),
            method_spec("pngail", importance_weighted_coef=values["importance_weighted_coef"]),
            jax.random.fold_in(jax.random.key(0), 0),
        )
        picked = jax.tree.map(lambda x, i=index: x[i], inputs)
        jax.tree.map(np.testing.assert_array_equal, picked[:2], by_hand[:2])
        _, metrics = single(*by_hand)
        for name in COMPARED:
            assert_close_across_programs(grid_metrics[name][index], metrics[name], name)
    kl = np.asarray(grid_metrics["trpo/kl"])
    assert np.all(kl[:2] <= 0.005 * 1.01) and kl[2:].max() > 0.005 * 1.01  # the axis acts
    with pytest.raises(ValueError, match="grid axes must be among"):
        make_cells(["gail"], 1, axes=(("num_envs", (4, 8)),))
