"""Every benchmark script runs on a tiny configuration and writes its rows, so none can fall out
of step with the library unnoticed (the numbers are not checked: they are timings)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def scripts_on_path(monkeypatch):
    """The scripts import their helper module, common.py, from their own folder."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))


def rows_of(module_name: str, argv: list[str], json_path: Path) -> list[dict]:
    module = __import__(module_name)
    module.main([*argv, "--json", str(json_path)])
    rows = json.loads(json_path.read_text())
    assert rows and all(row["device"] and row["jax_version"] for row in rows)
    return rows


def authors_pendulum_file(directory: Path, num_rows: int) -> Path:
    """A random file in the authors' Pendulum layout (rows [obs, action / 2]) with its
    confidence file beside it."""
    rng = np.random.default_rng(0)
    mixture = directory / "Pendulum-v1_mixture.npy"
    np.save(mixture, rng.normal(size=(num_rows, 4)).astype(np.float32))
    np.save(directory / "Pendulum-v1_mixture_conf.npy", rng.uniform(size=(num_rows, 1)))
    return mixture


def positive(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def test_every_benchmark_has_a_smoke_test():
    scripts = {path.stem for path in BENCHMARKS.glob("*.py")} - {"common"}
    tested = {name.removeprefix("test_") for name in globals() if name.startswith("test_")}
    assert scripts <= tested, f"benchmarks without a smoke test: {sorted(scripts - tested)}"


def test_common_markdown_table_and_rows(tmp_path):
    import common

    table = common.markdown_table(["a", "b"], [["x", "1.0"]], "lr")
    assert table == "| a | b |\n|---|---:|\n| x | 1.0 |"
    with pytest.raises(ValueError, match="one cell per column"):
        common.markdown_table(["a", "b"], [["x"]], "lr")
    common.write_rows(tmp_path / "sub" / "rows.json", [{"a": 1}])
    assert json.loads((tmp_path / "sub" / "rows.json").read_text()) == [{"a": 1}]
    assert common.mebibytes(None) == "-" and common.mebibytes(2**21) == "2.0"


def test_env_throughput(tmp_path):
    argv = ["--envs", "Pendulum-v1", "--widths", "4", "--out", str(tmp_path / "out")]
    rows = rows_of("env_throughput", argv, tmp_path / "rows.json")
    assert [row["width"] for row in rows] == [4] and positive(rows[0]["steps_per_second"])
    assert (tmp_path / "out" / "env_throughput.md").read_text().startswith("| env |")


def test_grid_throughput(tmp_path):
    # 4 iterations: at 1, a loaded machine timed the evaluation as long as the whole chunk
    argv = [
        "--env", "Pendulum-v1", "--sizes", "1", "--iterations", "4", "--classifier-steps", "10",
        "--no-compile-times", "--num-envs", "4", "--unroll-length", "50",
    ]  # fmt: skip
    (row,) = rows_of("grid_throughput", argv, tmp_path / "rows.json")
    assert row["cells"] == 1 and positive(row["steps_per_second"])
    assert positive(row["env_steps_per_second"]) and row["nonfinite_cells"] == 0


def test_trpo_throughput(tmp_path):
    argv = ["--envs", "Pendulum-v1", "--seeds", "1", "--iterations", "1"]
    rows = rows_of("trpo_throughput", argv, tmp_path / "rows.json")
    assert len(rows) == 4
    assert all(row["finite"] and positive(row["steps_per_second"]) for row in rows)


def test_iteration_phases(tmp_path):
    argv = ["--cells", "1", "--num-envs", "4", "--unroll-length", "50", "--demo-rows", "100",
            "--rounds", "1"]  # fmt: skip
    rows = rows_of("iteration_phases", argv, tmp_path / "rows.json")
    assert all(positive(row["milliseconds"]) for row in rows)
    phases = {row["phase"] for row in rows}
    assert {"gae/sequential", "gae/associative", "line_search/all_fractions"} <= phases


def test_classifier_throughput(tmp_path):
    mixture = authors_pendulum_file(tmp_path, 50)
    argv = ["--demos", str(mixture), "--seeds", "2", "--steps", "20", "--batch-sizes", "1"]
    (row,) = rows_of("classifier_throughput", argv, tmp_path / "rows.json")
    assert row["runs"] == 4 and 0 <= row["bsc_mae"] <= 1 and positive(row["run_seconds"])


def test_physics_agreement(tmp_path):
    argv = ["--tasks", "Hopper-v4", "--physics", "c", "--steps", "20"]
    (row,) = rows_of("physics_agreement", argv, tmp_path / "rows.json")
    # The C engine is gymnasium's own physics: the same trajectory to float rounding.
    assert row["physics"] == "c" and abs(row["return_difference"]) < 1e-6


@pytest.mark.heavy
def test_solver_accuracy(tmp_path):
    argv = ["--envs", "Hopper", "--num-envs", "2", "--steps", "10"]
    rows = rows_of("solver_accuracy", argv, tmp_path / "rows.json")
    assert {row["env"] for row in rows} == {"Hopper"} and all(
        positive(row["steps_per_s"]) for row in rows
    )


def test_method_cost(tmp_path):
    mixture = authors_pendulum_file(tmp_path, 100)
    argv = ["--demos", str(mixture), "--methods", "gail", "--quick", "--num-envs", "4",
            "--unroll-length", "50"]  # fmt: skip
    (row,) = rows_of("method_cost", argv, tmp_path / "rows.json")
    assert row["method"] == "gail" and row["ratio_to_first"] == 1.0
    assert positive(row["iteration_seconds"]) and positive(row["init_seconds"])


def test_offline_throughput(tmp_path):
    mixture = authors_pendulum_file(tmp_path, 50)
    argv = ["--demos", str(mixture), "--methods", "bc-all,iswbc", "--seeds", "1", "--steps",
            "2", "--iterations", "1", "--batch-size", "4"]  # fmt: skip
    rows = rows_of("offline_throughput", argv, tmp_path / "rows.json")
    assert [row["methods"] for row in rows] == ["bc-all,iswbc", "bc-all", "iswbc"]
    assert all(positive(row["steps_per_second_per_cell"]) for row in rows)
    assert positive(rows[0]["over_separate_ratio"])


@pytest.mark.heavy  # compiles MJX Hopper twice (its env-only scan and a one-cell grid)
def test_gpu_check(tmp_path):
    """The prepared GPU check at its tiny size: every step of its plan ran (Pendulum's grid
    with the paper-budget estimate, env-only and training per installed GPU engine)."""
    module = __import__("gpu_check")
    rows = module.main(["--tiny", "--minutes", "15", "--json", str(tmp_path / "rows.json")])
    assert json.loads((tmp_path / "rows.json").read_text()) == rows
    assert all(row["status"] == "ok" for row in rows), [row["status"] for row in rows]
    steps = [(row["step"], row["engine"]) for row in rows]
    engines = module.gpu_engines()
    assert steps[0] == ("pendulum paper grid", "-") and rows[0]["paper_grid_seconds"] > 0
    for engine in engines:
        assert ("env only", engine) in steps and ("training", engine) in steps
    training = [row for row in rows if row["step"] == "training"]
    assert all(positive(row["steps_per_second_with_eval"]) for row in training)
    assert "the paper's grid" in module.table(rows)
    skipped = module.run_step(module.plan(tiny=True)[0], 0.0, tmp_path)
    assert skipped[0]["status"] == "skipped: no time left"
    full = [step for step in module.plan(tiny=False) if step.name == "training"]
    for step in full:  # each task trains on the GPU preset's caps
        caps = module.GPU_SOLVERS.get(step.task)
        assert (("--solver", caps) == step.argv[5:7]) if caps else "--solver" not in step.argv


def test_fisher_roofline(tmp_path):
    argv = ["--samples", "50", "--hidden", "8", "--products", "2", "--repeats", "1"]
    rows = rows_of("fisher_roofline", argv, tmp_path / "rows.json")
    assert [row["name"] for row in rows] == ["fisher_roofline/products", "fisher_roofline/matmuls"]
    assert all(positive(row["milliseconds"]) and positive(row["over_matmuls"]) for row in rows)
    assert rows[1]["over_matmuls"] == 1.0


def test_cold_start(tmp_path):
    """One cold and one warm process of a tiny Pendulum sweep: every stage and both
    programs' compile and size are measured, and the warm process reads both of the cold
    one's programs from the cache (one hit each)."""
    mixture = authors_pendulum_file(tmp_path, 100)
    extra = (
        f"--demos {mixture} --num-envs 4 --unroll-length 50 --iterations 2 --eval-every 2 "
        "--chunk-iterations 2 --classifier-steps 5 --num-eval-episodes 2"
    )
    argv = ["--cases", "pendulum", "--repeats", "1", "--cpus", "", "--extra", extra]
    rows = rows_of("cold_start", argv, tmp_path / "rows.json")
    assert [row["cache"] for row in rows] == ["cold", "warm"]
    for row in rows:
        assert all(row["stages"][stage] >= 0 for stage in row["stages"])
        assert positive(row["total_seconds"]) and row["total_seconds"] >= row["stages"]["build"]
        for program in ("init", "chunk"):
            size = row["programs"][program]
            assert size["hlo_instructions"] > 100 and size["stablehlo_lines"] > 100
            assert sum(size["sources"].values()) <= size["hlo_instructions"]
    for program in ("init", "chunk"):  # the warm process reads both from the cache
        cold, warm = (row["programs"][program] for row in rows)
        assert cold["backend_seconds"] > 0 and cold["cache_hits"] == 0, program
        assert warm["cache_hits"] == 1 and warm["cache_seconds"] > 0, program


def test_vs_imitation(tmp_path):
    """What needs no imitation: the rows the peer is fed (the authors' file's torque scale
    applied, clipped to the bound, each row's next row in its own trajectory), the peer's
    batches, our sweep's command line and the tables from made-up runs."""
    module = __import__("vs_imitation")
    stored = np.zeros((400, 4), np.float32)
    stored[:, :3] = np.arange(1200, dtype=np.float32).reshape(400, 3)
    stored[:3, 3] = [-3.0, 0.5, 1.5]  # torque / 2, as the authors store it
    np.save(tmp_path / "Pendulum-v1_mixture.npy", stored)
    np.save(tmp_path / "Pendulum-v1_mixture_conf.npy", np.repeat([[0.2], [0.9]], 200, axis=0))
    rows, return_range = module.peer_rows(str(tmp_path / "Pendulum-v1_mixture.npy"))
    assert return_range == (-1200.96, -116.81)  # the paper's Table 3 for Pendulum
    np.testing.assert_array_equal(rows["acts"][:4, 0], [-2.0, 1.0, 2.0, 0.0])  # 2x, clipped
    np.testing.assert_array_equal(rows["next_obs"][:199], rows["obs"][1:200])
    np.testing.assert_array_equal(rows["next_obs"][[199, 399]], rows["obs"][[199, 399]])
    assert np.flatnonzero(rows["dones"]).tolist() == [199, 399]
    batch = next(iter(module.DrawnRows(rows, 1000, seed=0)))
    assert batch["obs"].shape == (1000, 3) and len(np.unique(batch["obs"][:, 0])) < 400
    # Each drawn row keeps its own fields together: obs row i is 3i, 3i+1, 3i+2.
    np.testing.assert_array_equal(batch["obs"][:, 1], batch["obs"][:, 0] + 1)

    args = module.parse_args(["--budgets", "500000"])
    command = module.our_command(args, 500_000, 2, tmp_path)
    assert command[command.index("--iterations") + 1] == "100" and "--eval-every" not in command
    assert command[command.index("--seed") + 1] == "2"
    quick = module.parse_args(["--quick"])
    assert quick.budgets == "10000" and quick.seeds == 1
    assert module.our_command(quick, 10_000, 0, tmp_path)[-4:] == [
        "--chunk-iterations", "2", "--eval-every", "2",
    ]  # fmt: skip

    def run(library, seed, seconds, rate):
        return {
            "library": library, "budget": 500_000, "seed": seed, "total_seconds": seconds,
            "total_cpu_seconds": seconds - 10, "train_env_steps_per_second": rate,
            "final_normalized_return": 0.1 * seed,
        }  # fmt: skip

    made = [run("pngail-jax", 0, 40.0, 40_000.0), run("pngail-jax", 1, 50.0, 50_000.0),
            run("imitation", 0, 150.0, 6_000.0), run("imitation", 1, 160.0, 6_000.0)]  # fmt: skip
    # Rate 45,000 / 6,000 = 7.5x; whole process 155 / 45 = 3.4x, in CPU 145 / 35 = 4.1x.
    assert "| 500,000 | 7.5x | 3.4x | 4.1x | 3x: wall met, CPU met |" in module.ratio_table(made)
    line = "| pngail-jax | 500,000 | 2 | 45,000 ± 5,000 | 45.0 ± 5.0 | 35.0 ± 5.0 | 0.05 ± 0.05 |"
    assert line in module.runs_table(made)


def peer_interpreter() -> str:
    """The benchmark's default peer interpreter, or skip: imitation is an optional extra of
    the benchmark, never a test dependency."""
    import subprocess

    python = __import__("vs_imitation").parse_args([]).peer_python
    if Path(python).exists():
        check = [python, "-c", "import imitation, sb3_contrib"]
        found = subprocess.run(check, capture_output=True, check=False).returncode == 0
    else:
        found = False
    if not found:
        pytest.skip(f"no interpreter with imitation at {python} (benchmarks/peer-requirements.txt)")
    return python


@pytest.mark.heavy  # a cold compile of our sweep and imitation's imports, two processes
def test_vs_imitation_runs_both_libraries(tmp_path):
    peer_interpreter()
    mixture = authors_pendulum_file(tmp_path, 1000)
    argv = ["--quick", "--demos", str(mixture), "--num-envs", "4", "--unroll-length", "50",
            "--cpus", ""]  # fmt: skip
    rows = rows_of("vs_imitation", argv, tmp_path / "rows.json")
    assert sorted(row["library"] for row in rows) == ["imitation", "pngail-jax"]
    for row in rows:
        assert row["budget"] == 400 and positive(row["total_seconds"])
        assert 0 < row["total_cpu_seconds"] <= 2 * row["total_seconds"]
        assert positive(row["train_env_steps_per_second"])
        assert math.isfinite(row["final_normalized_return"])
    assert rows[1]["versions"]["imitation"] == "1.0.1"
