import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest


def run_x64(test_file: str, function_name: str) -> dict:
    """Runs ``function_name()`` from ``test_file`` in a fresh Python with float64 JAX.

    Toggling ``jax_enable_x64`` inside one process can reuse a float32 lowering of a nested
    jitted helper (seen with MJX's RK4 integrator), so x64 checks run in their own process.
    The function returns a JSON-serialisable dict, which is returned here.
    """
    return run_in_subprocess(test_file, function_name, {"JAX_ENABLE_X64": "1"})


def run_in_subprocess(test_file: str, function_name: str, environment: dict) -> dict:
    """Runs ``function_name()`` from ``test_file`` in a fresh Python with ``environment``
    added to the environment variables (settings fixed at JAX start-up, e.g. XLA_FLAGS)."""
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


def tiny_sweep_args(demos_path, out):
    return [
        "--demos", str(demos_path), "--methods", "gail,pngail", "--seeds", "2",
        "--iterations", "4", "--eval-every", "1", "--chunk-iterations", "2",
        "--num-envs", "4", "--unroll-length", "50", "--classifier-steps", "50",
        "--cpu-devices", "1", "--out", str(out),
    ]  # fmt: skip
