import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


def pytest_configure(config):
    """The suite compiles through JAX's persistent compilation cache, as the programs do: in
    ``$PNGAIL_JAX_COMPILATION_CACHE`` (else ``~/.cache/pngail-jax/xla``), for this process and,
    through JAX's own environment variables, for the fresh interpreters that some tests start.
    Tests that build the same program (a tiny sweep in-process and again in a subprocess, the
    same environment rolled out by two modules, both xdist workers) then compile it once; a
    second run of the suite on the same machine reads every program from disk. A test never
    depends on the cache: an empty folder gives the same results, only slower."""
    from pngail_jax.storage.compilation import enable_compilation_cache

    directory = enable_compilation_cache()
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(directory))
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")


def run_x64(test_file: str, function_name: str) -> dict:
    """Runs ``function_name()`` from ``test_file`` in a fresh Python with float64 JAX.

    Toggling ``jax_enable_x64`` inside one process can reuse a float32 lowering of a nested
    jitted helper (seen with MJX's RK4 integrator), so x64 checks run in their own process.
    The function returns a JSON-serialisable dict, which is returned here.
    """
    return run_in_subprocess(test_file, function_name, {"JAX_ENABLE_X64": "1"})


def run_in_subprocess(
    test_file: str, function_name: str, environment: dict, cpus: set[int] | None = None
) -> dict:
    """Runs ``function_name()`` from ``test_file`` in a fresh Python with ``environment``
    added to the environment variables (settings fixed at JAX start-up, e.g. XLA_FLAGS),
    on the CPUs ``cpus`` only if given (the process's affinity from its start, as
    ``taskset`` sets it: what XLA sizes its thread pools by)."""
    code = (
        "import json, runpy, sys\n"
        f"sys.path.insert(0, {os.path.dirname(os.path.abspath(test_file))!r})\n"
        f"namespace = runpy.run_path({test_file!r})\n"
        f"print('RESULT ' + json.dumps(namespace[{function_name!r}]()))\n"
    )
    env = {**os.environ, **environment}
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None,
    )
    results = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    assert done.returncode == 0 and results, f"subprocess failed:\n{done.stderr[-3000:]}"
    return json.loads(results[-1].removeprefix("RESULT "))


def authors_data() -> Path:
    """The folder of the authors' released demonstrations: the documented download folder
    ``data/released`` of this checkout (docs/demonstrations.md), else the copy beside the
    checkout that the project's machines and CI have (``../shared/data/released``). Tests
    that need a file skip when it is in neither."""
    root = Path(__file__).resolve().parents[1]
    candidates = (root / "data" / "released", root.parent / "shared" / "data" / "released")
    return next((folder for folder in candidates if folder.exists()), candidates[0])


def as_sweep_run(directory: Path, return_range, **config) -> Path:
    """``directory`` (a metrics.csv written by hand, perhaps a summary.json) made a sweep run
    the programs trust (``runs.verify_run``): marked as the sweep's, with a sealed config.json
    naming the ``return_range`` its normalised returns were written with (under the older
    layouts' key ``normalizer``, which every reader still takes), and ``config``."""
    from pngail_jax.analysis.runs import sealed_part
    from pngail_jax.storage.integrity import CONFIG_SEAL, seal
    from pngail_jax.storage.outputs import prepare_output

    prepare_output(directory, "sweep")
    document = {**config, "resolved": {"normalizer": list(return_range)}}
    (Path(directory) / "config.json").write_text(json.dumps(document))
    seal(Path(directory) / CONFIG_SEAL, sealed_part(document))
    return Path(directory)


def metrics_numbers(path: Path) -> list[dict]:
    """A sweep's metrics.csv without its wall-clock column: what a resumed or repeated run must
    reproduce exactly (the wall clock is the one field that differs between two runs)."""
    import csv

    with open(path) as file:
        rows = list(csv.DictReader(file))
    assert rows and "wall_seconds" in rows[0], path
    return [{k: v for k, v in row.items() if k != "wall_seconds"} for row in rows]


# -- a tiny sweep (Pendulum-v1, 100 rows, 2 methods x 2 seeds x 4 iterations) ---------------
# Shared by the sweep's and the runner's tests.


@pytest.fixture(scope="module")
def demos_path(tmp_path_factory):
    from pngail_jax.demos import Demonstrations, save_npz

    rng = np.random.default_rng(0)
    demos = Demonstrations(
        observations=rng.normal(size=(100, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(100, 1)).astype(np.float32),
        confidence=np.repeat([1.0, 0.4, 0.45, 0.5, 0.35], 20).astype(np.float32),
        metadata={"env": "Pendulum-v1", "random_return": -1200.0, "optimal_return": -150.0},
    )
    path = tmp_path_factory.mktemp("demos") / "demos.npz"
    save_npz(path, demos)
    return path


def sigterm_to_self(*args, wait: float = 30.0, **kwargs):
    """Stands in for a program's work: this process gets the SIGTERM a batch scheduler sends
    at a job's time limit, then sleeps ``wait`` seconds (a handler that stops at once raises
    within the sleep; one that defers the stop returns, and the sleep goes on)."""
    import os
    import signal
    import time

    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(wait)


def tiny_sweep_args(demos_path, out):
    return [
        "--demos", str(demos_path), "--methods", "gail,pngail", "--seeds", "2",
        "--iterations", "4", "--eval-every", "1", "--chunk-iterations", "2",
        "--num-envs", "4", "--unroll-length", "50", "--classifier-steps", "50",
        "--cpu-devices", "1", "--out", str(out),
    ]  # fmt: skip


def tiny_offline_demos():
    """The offline tests' tiny set: 200 random Pendulum-v1 rows in 10 trajectories of 20, with
    confidences 1, 0.2, 0.7 and 0 by blocks of 50."""
    from pngail_jax.demos import Demonstrations

    rng = np.random.default_rng(0)
    return Demonstrations(
        observations=rng.normal(size=(200, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(200, 1)).astype(np.float32),
        confidence=np.repeat([1.0, 0.2, 0.7, 0.0], 50).astype(np.float32),
        trajectory_ids=np.repeat(np.arange(10), 20),
        metadata={"env": "Pendulum-v1"},
    )


# -- demonstrations of a classical controller (no file needed) ------------------------------


def swing_up_action(observation) -> float:
    """A hand-written Pendulum-v1 controller: pump energy towards the upright position's
    (bang-bang on the sign of thdot * (E* - E)), then hold it with a PD law. Over 50 seeds of
    gymnasium's Pendulum-v1 it returns -140 on average (min -365, max 0); the paper's
    optimal policy scores -116.8 and the random one about -1200."""
    cos, sin, velocity = (float(x) for x in observation)
    if cos > 0.85:  # near upright: hold
        torque = -10.0 * math.atan2(sin, cos) - 2.0 * velocity
    else:  # E = thdot^2 / 6 + 5 cos(th) per unit mass and length; upright E* = 5
        energy = velocity**2 / 6 + 5.0 * cos
        torque = (
            2.0 * math.copysign(1.0, velocity * (5.0 - energy)) if abs(velocity) > 1e-3 else 2.0
        )
    return min(max(torque, -2.0), 2.0)


def _pendulum_demonstrations(episodes, confidences):
    """One episode of gymnasium's Pendulum-v1 per ``(torque_of, seed)`` pair in ``episodes``
    (``torque_of(observation) -> float``), as ``Demonstrations`` whose rows of episode k have
    confidence ``confidences[k]``, one trajectory each, and the episodes' returns."""
    import gymnasium as gym

    from pngail_jax.demos import Demonstrations

    env = gym.make("Pendulum-v1")
    observations, actions, ids, returns = [], [], [], []
    for episode, (torque_of, seed) in enumerate(episodes):
        observation, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            action = np.array([torque_of(observation)], np.float32)
            observations.append(observation)
            actions.append(action)
            ids.append(episode)
            observation, reward, terminated, truncated, _ = env.step(action)
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    ids = np.asarray(ids)
    demos = Demonstrations(
        observations=np.asarray(observations, np.float32),
        actions=np.asarray(actions, np.float32),
        confidence=np.asarray(confidences, np.float32)[ids],
        trajectory_ids=ids,
    )
    return demos, returns


def swing_up_mixture(num_random: int = 4, seed: int = 0):
    """A 1:``num_random`` mixture with known confidences and no file: one episode of
    ``swing_up_action`` (confidence 1, return -123) and ``num_random`` episodes of uniform
    random torques (confidence 0, returns -1,130 to -1,580), 200 rows each, on gymnasium's
    Pendulum-v1 (seeds ``seed``, ``seed + 10``, ...). GAIL imitates the whole mixture, so
    mostly the random rows; a method that reads the confidences should not."""
    rng = np.random.default_rng(seed)

    def random_torque(observation):
        return rng.uniform(-2, 2)

    episodes = [(swing_up_action, seed)] + [
        (random_torque, seed + 10 * k) for k in range(1, 1 + num_random)
    ]
    return _pendulum_demonstrations(episodes, [1.0] + [0.0] * num_random)


def swing_up_episodes_and_random(num_controller: int, num_random: int):
    """``num_controller`` episodes of ``swing_up_action`` (seeds 0, 1, ...; confidence 1,
    returns -240 to 0) and ``num_random`` of uniform random torques (seeds 100, 101, ...;
    confidence 0, about -1,400), one trajectory each, and their returns: a mixture of many
    trajectories, for methods that rank or weight whole trajectories or learn from a share of
    labelled rows."""
    rng = np.random.default_rng(0)

    def random_torque(observation):
        return rng.uniform(-2, 2)

    episodes = [(swing_up_action, seed) for seed in range(num_controller)] + [
        (random_torque, 100 + seed) for seed in range(num_random)
    ]
    return _pendulum_demonstrations(episodes, [1.0] * num_controller + [0.0] * num_random)


def noisy_swing_up_episodes(shares):
    """One episode of ``swing_up_action`` per share eps in ``shares`` (seeds 100, 101, ...),
    each torque replaced by a uniform random one with probability eps, confidence 1 - eps, one
    trajectory each, and their returns: trajectories of graded quality."""
    rng = np.random.default_rng(0)

    def noisy(share):
        def torque_of(observation):
            return rng.uniform(-2, 2) if rng.uniform() < share else swing_up_action(observation)

        return torque_of

    episodes = [(noisy(share), 100 + index) for index, share in enumerate(shares)]
    return _pendulum_demonstrations(episodes, [1 - share for share in shares])


def swing_up_demonstrations(num_episodes: int = 1, seed: int = 0):
    """``num_episodes`` episodes of ``swing_up_action`` on gymnasium's Pendulum-v1 (seeds
    ``seed``, ``seed + 1``, ...) as ``Demonstrations`` of confidence 1, one trajectory each,
    and their returns."""
    episodes = [(swing_up_action, seed + k) for k in range(num_episodes)]
    return _pendulum_demonstrations(episodes, [1.0] * num_episodes)
