"""gymnasium's -v4 MuJoCo tasks on MuJoCo's C engine against gymnasium itself, step for step."""

import json
import shutil

import gymnasium as gym
import jax
import numpy as np
import pytest
from conftest import metrics_numbers, run_x64

from pngail_jax import envs

NUM_STEPS = 1000


def _gymnasium_episode(name: str, seed: int, num_steps: int = NUM_STEPS, **options):
    """gymnasium's env from ``reset(seed)``, stepped with uniform actions up to 1.2x the bounds
    (MuJoCo clamps them; the control cost uses them as given). Stepping goes on past a
    termination (``unwrapped``: no order enforcing), so every task is compared for
    ``num_steps`` steps, unhealthy states included."""
    reference = gym.make(name, **options).unwrapped
    reference.reset(seed=seed)
    qpos, qvel = reference.data.qpos.copy(), reference.data.qvel.copy()
    rng = np.random.default_rng(seed)
    low, high = reference.action_space.low, reference.action_space.high
    rows = []
    for _ in range(num_steps):
        action = rng.uniform(1.2 * low, 1.2 * high)
        obs, reward, terminated, _, _ = reference.step(action)
        rows.append((action, obs, reward, terminated))
    actions, obs, rewards, terminated = (np.array(column) for column in zip(*rows, strict=True))
    return qpos, qvel, actions, obs, rewards, terminated


def _our_episode(env, qpos, qvel, actions):
    step = jax.jit(env.step)
    template = jax.jit(env.reset)(jax.random.key(0))
    obs, internal = jax.jit(env.state_at)(qpos, qvel)
    state = template.replace(obs=obs, internal=internal)
    rows = []
    for action in actions:
        state = step(state, action)
        rows.append((state.obs, state.reward, state.done))
    return [np.array(column) for column in zip(*rows, strict=True)]


def x64_episode_errors() -> dict:
    """Runs in a float64 subprocess: per task, the largest |difference| from gymnasium."""
    assert jax.config.jax_enable_x64
    errors = {}
    never_ending = {"terminate_when_unhealthy": False}
    cases = [(name, {}) for name in envs.GYM_TASKS] + [("Hopper-v4", never_ending)]
    for seed, (name, options) in enumerate(cases):
        qpos, qvel, actions, obs, rewards, terminated = _gymnasium_episode(name, seed, **options)
        env = envs.make(name, physics="c", **options)
        our_obs, our_rewards, our_terminated = _our_episode(env, qpos, qvel, actions)
        assert our_obs.dtype == np.float64
        errors[f"{name} {options}"] = {
            "obs": float(np.abs(our_obs - obs).max()),
            "reward": float(np.abs(our_rewards - rewards).max()),
            "terminations_differ": int((our_terminated != terminated).sum()),
            "terminations": int(terminated.sum()),
        }
    return errors


def test_c_engine_equals_gymnasium_over_whole_episodes_in_float64():
    """Bit for bit: the same MuJoCo, the same float64 state (warm start included) and
    gymnasium's order of operations in the reward."""
    errors = run_x64(__file__, "x64_episode_errors")
    for name, error in errors.items():
        assert error["obs"] == 0.0 and error["reward"] == 0.0, (name, error)
        assert error["terminations_differ"] == 0, (name, error)
    # Stepping past terminations compared unhealthy states as well as healthy ones.
    assert errors["Hopper-v4 {}"]["terminations"] > 100


@pytest.mark.parametrize("name", ["HalfCheetah-v4", "Hopper-v4"])
def test_c_engine_is_float64_exact_even_when_jax_is_float32(name):
    """The physics state crosses JAX as float64 bytes and the step's outcome is computed in
    float64 on the host, so in float32 JAX observations and rewards are gymnasium's rounded
    once to float32 (equal, not merely close, after 1000 steps), terminations the same."""
    assert not jax.config.jax_enable_x64
    qpos, qvel, actions, *_ = _gymnasium_episode(name, seed=7)
    env = envs.make(name, physics="c")
    our_obs, our_rewards, our_terminated = _our_episode(env, qpos, qvel, actions.astype(np.float32))
    assert our_obs.dtype == our_rewards.dtype == np.float32
    # Our start state and actions are float32: replay gymnasium from the same rounded values.
    reference = gym.make(name).unwrapped
    reference.reset(seed=7)
    reference.set_state(qpos.astype(np.float32), qvel.astype(np.float32))
    expected = [reference.step(a.astype(np.float32))[:3] for a in actions]
    expected_obs, expected_rewards, expected_terminated = (
        np.array(c) for c in zip(*expected, strict=True)
    )
    np.testing.assert_array_equal(our_obs, expected_obs.astype(np.float32))
    np.testing.assert_array_equal(our_rewards, expected_rewards.astype(np.float32))
    np.testing.assert_array_equal(our_terminated, expected_terminated)


def test_spaces_match_gymnasium():
    for name in envs.GYM_TASKS:
        env = envs.make(name, physics="c")
        reference = gym.make(name)
        assert env.observation_size == reference.observation_space.shape[0], name
        assert env.action_size == reference.action_space.shape[0], name
        np.testing.assert_array_equal(env.action_low, reference.action_space.low)
        np.testing.assert_array_equal(env.action_high, reference.action_space.high)
        assert env.max_episode_steps == reference.spec.max_episode_steps == 1000
        assert env.dt == pytest.approx(reference.unwrapped.dt)


@pytest.mark.parametrize("name", ["Hopper-v4", "HalfCheetah-v4"])
def test_reset_distribution(name):
    env = envs.make(name, physics="c")
    spec = env.spec
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), 4000))
    qpos0 = gym.make(name).unwrapped.init_qpos
    bits = np.asarray(states.internal.bits).reshape(len(states.obs), -1)
    state = bits.view(np.float64)
    nq = len(qpos0)
    qpos = state[:, 1 : 1 + nq]  # after the time
    qvel = state[:, 1 + nq : 1 + 2 * nq]
    scale = spec.reset_noise_scale
    assert np.abs(qpos - qpos0).max() <= scale
    np.testing.assert_allclose((qpos - qpos0).std(axis=0), scale / np.sqrt(3), rtol=0.1)
    expected_std = scale if spec.normal_velocity_noise else scale / np.sqrt(3)
    np.testing.assert_allclose(qvel.std(axis=0), expected_std, rtol=0.1)
    np.testing.assert_array_equal(state[:, 0], 0.0)  # time
    np.testing.assert_array_equal(state[:, -1], qpos[:, 0])  # the first step's start x
    expected = np.array([spec.observe(np, p, v) for p, v in zip(qpos, qvel, strict=True)])
    np.testing.assert_array_equal(states.obs, expected.astype(np.float32))


def _hopper_grid_setup():
    """3 methods x 2 seeds on Hopper-v4 (C engine), 4 envs x 20 steps, 50-step episodes."""
    from test_grid import small_grid_inputs

    from pngail_jax.adversarial.trainer import AdversarialConfig, AdversarialTrainer
    from pngail_jax.confidence import ClassifierConfig
    from pngail_jax.demos import Demonstrations
    from pngail_jax.rl import RolloutConfig

    env = envs.make("Hopper-v4", physics="c", max_episode_steps=50)
    rng = np.random.default_rng(0)
    demos = Demonstrations(
        observations=rng.normal(size=(120, 11)).astype(np.float32),
        actions=rng.uniform(-1, 1, size=(120, 3)).astype(np.float32),
        confidence=np.repeat(rng.uniform(0.2, 1.0, 6), 20).astype(np.float32),
    )
    rollout = RolloutConfig(
        num_envs=4, unroll_length=20, num_iterations=2, eval_every=1, num_eval_episodes=2
    )
    config = AdversarialConfig(rollout=rollout, classifier=ClassifierConfig(num_steps=20))
    return AdversarialTrainer(config, env, demos), small_grid_inputs()


@pytest.mark.heavy
@pytest.mark.slow
def test_c_engine_grid_cells_equal_single_runs():
    """The callback under jit(vmap) over cells: the grid's first chunk equals each cell run
    alone (the physics is exact per env; only XLA's float32 reductions may differ between
    the two programs)."""
    from test_grid import COMPARED, assert_close_across_programs

    from pngail_jax.grid import Grid

    trainer, (cells, inputs) = _hopper_grid_setup()
    grid = Grid(trainer, inputs, blocks_per_chunk=1)
    state, _ = grid.init()
    _, first = grid.run_chunk(state)
    first = grid.fetch(first)
    single = jax.jit(trainer.train)
    for index in (0, len(cells) - 1):
        one = single(*jax.tree.map(lambda x, i=index: x[i], inputs))[1]
        for name in COMPARED:
            assert_close_across_programs(np.asarray(one[name])[:1], first[name][index], name)


@pytest.mark.heavy
@pytest.mark.slow
def test_c_engine_sweep_resumed_after_a_kill_equals_the_uninterrupted_run(tmp_path):
    sweep_resumes_bit_exactly(tmp_path, "c")


def sweep_resumes_bit_exactly(tmp_path, physics: str):
    """The sweep on Hopper-v4 on ``physics``: chunks, checkpoints and --resume as on any task.
    A copy of a finished run cut back to its first checkpoint (what a kill after it leaves;
    tests/test_sweep.py kills a run for real) resumes to the same metrics, bit for bit;
    config.json records the engine, and a resume keeps it. Returns the uninterrupted run."""
    from pngail_jax.demos import Demonstrations, save_npz
    from pngail_jax.jobs import record
    from pngail_jax.programs import sweep

    rng = np.random.default_rng(0)
    demos = Demonstrations(
        observations=rng.normal(size=(60, 11)).astype(np.float32),
        actions=rng.uniform(-1, 1, size=(60, 3)).astype(np.float32),
        confidence=np.repeat([1.0, 0.4, 0.5], 20).astype(np.float32),
        metadata={"env": "Hopper-v4", "random_return": 18.0, "optimal_return": 3250.0},
    )
    save_npz(tmp_path / "demos.npz", demos)
    whole = tmp_path / "whole"
    sweep.main(
        ["--env", "Hopper-v4", "--demos", str(tmp_path / "demos.npz"), "--methods", "gail,pngail",
         "--seeds", "1", "--iterations", "4", "--eval-every", "1", "--chunk-iterations", "2",
         "--num-envs", "4", "--unroll-length", "20", "--num-eval-episodes", "2",
         "--classifier-steps", "20", "--physics", physics, "--out", str(whole)]
    )  # fmt: skip
    saved = json.loads((whole / "config.json").read_text())
    assert saved["config"]["env"] == "Hopper-v4" and saved["resolved"]["physics"] == physics
    killed = tmp_path / "killed"
    shutil.copytree(whole, killed)
    shutil.rmtree(killed / "checkpoints" / "chunk_0002")
    shutil.rmtree(killed / "policies")
    for name in ("metrics.csv", "summary.json", "summary.md", "curves.png"):
        (killed / name).unlink()
    assert record.load_saved(killed).config.settings.physics == physics
    sweep.main(["--resume", str(killed)])
    assert metrics_numbers(killed / "metrics.csv") == metrics_numbers(whole / "metrics.csv")
    resumed, uninterrupted = (
        np.load(run / "checkpoints" / "chunk_0002" / "metrics.npz") for run in (killed, whole)
    )
    for name in uninterrupted.files:
        np.testing.assert_array_equal(resumed[name], uninterrupted[name], err_msg=name)
    return whole


@pytest.mark.heavy
@pytest.mark.slow
@pytest.mark.parametrize("name", ["Hopper-v4"])
def test_the_mjx_path_follows_gymnasium_over_50_steps(name):
    """The -v4 tasks on MJX (float32, gymnasium's solver settings) against gymnasium's C engine
    (float64) from the same state and actions: within 1e-4 in every observation entry and
    reward over 50 steps, terminations the same (measured: Hopper 7.4e-6, Swimmer 4.2e-6,
    Walker2d 8.1e-5). HalfCheetah and Ant agree to 2e-6 on the first step and then part
    (1.6e-3 and 0.63 by step 10): their contacts amplify float32 rounding and MJX's own
    contact solver (docs/environments.md). Hopper here, the task with contacts and
    terminations that agrees (each MJX model compiles for half a minute on 2 cores; Swimmer's
    MJX model is tested against gymnasium in tests/test_swimmer.py)."""
    qpos, qvel, actions, obs, rewards, terminated = _gymnasium_episode(name, 3, num_steps=50)
    env = envs.make(name, physics="mjx")
    our_obs, our_rewards, our_terminated = _our_episode(env, qpos, qvel, actions.astype(np.float32))
    np.testing.assert_allclose(our_obs, obs, rtol=0, atol=1e-4)
    np.testing.assert_allclose(our_rewards, rewards, rtol=0, atol=1e-4)
    np.testing.assert_array_equal(our_terminated, terminated)
    _check_reset_needs_no_forward_pass(env, qpos, qvel, actions[0].astype(np.float32))


def _check_reset_needs_no_forward_pass(env, qpos, qvel, action):
    """A reset leaves MJX's derived fields to the next step (which starts with a forward
    pass): stepping from it equals, bit for bit, stepping from data a forward pass filled."""
    step = jax.jit(env.step)
    state = jax.jit(env.reset)(jax.random.key(0))
    obs, internal = jax.jit(env.state_at)(qpos, qvel)
    bare = state.replace(obs=obs, internal=internal)
    full_data = jax.jit(env._mjx.forward)(env._mjx_model, internal.data)
    assert not np.array_equal(full_data.xpos, internal.data.xpos)  # the forward pass did work
    full = bare.replace(internal=internal.replace(data=full_data))
    a, b = step(bare, action), step(full, action)
    np.testing.assert_array_equal(a.obs, b.obs)
    np.testing.assert_array_equal(a.reward, b.reward)
    leaves = zip(jax.tree.leaves(a.internal), jax.tree.leaves(b.internal), strict=True)
    for leaf_a, leaf_b in leaves:
        np.testing.assert_array_equal(leaf_a, leaf_b)
