import json
import os
import subprocess
import sys
from pathlib import Path


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
