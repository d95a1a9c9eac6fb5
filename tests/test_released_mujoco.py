"""The authors' released MuJoCo files (synthetic stand-ins of the right shapes: the real files
are not in this repository) and the paper's per-task settings (Table 3, appendix C.2); and,
where the real files are at hand (conftest's ``authors_data``), learning on them: GAIL on
Hopper-v4 and BC on the expert rows on HalfCheetah-v4, on MuJoCo's C engine."""

import numpy as np
import pytest
from conftest import authors_data

from pngail_jax import envs
from pngail_jax.config.run_config import RunConfig
from pngail_jax.demos import DemonstrationError, load_released
from pngail_jax.jobs.trainer_configs import adversarial_config
from pngail_jax.programs import sweep

# The released files' shapes, [s, a] columns, and the paper's Table 3 for each task.
RELEASED = {
    # file env: (our task, observation columns, action columns, n_c + n_u, random, optimal)
    "HalfCheetah-v2": ("HalfCheetah-v4", 17, 6, 2500, -288.44, 3467.32),
    "Hopper-v2": ("Hopper-v4", 11, 3, 100, 18.04, 3250.67),
    "Swimmer-v2": ("Swimmer-v4", 8, 2, 25, 2.31, 348.99),
    "Walker2d-v2": ("Walker2d-v4", 17, 6, 2000, 1.91, 3694.13),
}


def write_released(directory, name: str, num_rows: int, num_columns: int, seed: int = 0):
    """``{name}_mixture.npy`` of rows [s, a] in [-1.5, 1.5] (the authors' actions go a little
    beyond the bounds) and its ``_mixture_conf.npy`` of shape (N, 1)."""
    rng = np.random.default_rng(seed)
    mixture = directory / f"{name}_mixture.npy"
    np.save(mixture, rng.uniform(-1.5, 1.5, (num_rows, num_columns)).astype(np.float32))
    np.save(directory / f"{name}_mixture_conf.npy", rng.uniform(0, 1, (num_rows, 1)))
    return mixture


@pytest.mark.parametrize("file_env", list(RELEASED))
def test_each_released_mujoco_file_fits_its_task_with_the_papers_settings(tmp_path, file_env):
    task, num_obs, num_actions, num_demos, random_return, optimal_return = RELEASED[file_env]
    mixture = write_released(tmp_path, file_env, 3000, num_obs + num_actions)
    demos = load_released(mixture)
    assert demos.observations.shape == (3000, num_obs) and demos.actions.shape[1] == num_actions
    assert (demos.metadata["random_return"], demos.metadata["optimal_return"]) == (
        random_return,
        optimal_return,
    )
    demos.check_env(envs.make(task))  # sizes and units fit our task
    demos.check_env(envs.make(envs.task_family(task)))  # and Brax's variant of it
    # --demos alone picks the task, and the split takes the paper's n_c + n_u, capped at the
    # file's 3,000 rows (HalfCheetah's 2,500 and Walker2d's 2,000 fit; so do the others).
    config = sweep.parse_args(["--demos", str(mixture), "--out", str(tmp_path / "run")]).config
    assert config.env == task
    assert config.task_num_demos(demos.num_rows) == min(num_demos, 3000)
    assert config.task_num_demos(40) == min(num_demos, 40)
    assert adversarial_config(config, demos.num_rows).num_demos == num_demos


def test_walker2d_takes_the_papers_classifier_and_clip():
    walker = RunConfig(env="Walker2d")
    assert walker.classifier.num_steps == 50_000 and walker.task_bsc_eps == 0.05
    assert RunConfig(env="Hopper").classifier.num_steps == 25_000
    # Another task through replace or the command line gets that task's classifier ...
    assert RunConfig().replace(env="Walker2d").classifier.num_steps == 50_000
    assert walker.replace(env="Hopper").classifier.num_steps == 25_000
    parsed = sweep.parse_args(["--env", "Walker2d", "--out", "unused"]).config
    assert parsed.classifier.num_steps == 50_000
    # ... unless one is given; and a given num_demos is used as it is.
    parsed = sweep.parse_args(["--env", "Walker2d", "--classifier-steps", "7", "--out", "x"])
    assert parsed.config.classifier.num_steps == 7
    assert RunConfig(env="Hopper", num_demos=5).task_num_demos(10_000) == 5


def test_a_released_file_of_another_task_is_named(tmp_path):
    hopper = load_released(write_released(tmp_path, "Hopper-v2", 10, 14))
    with pytest.raises(DemonstrationError, match="demonstrations of Hopper-v2 do not fit Swimmer"):
        hopper.check_env(envs.make("Swimmer"))
    with pytest.raises(DemonstrationError, match="pick the task Hopper-v4"):
        hopper.check_env(envs.make("Walker2d-v4"))
    ant = load_released(write_released(tmp_path, "Ant-v2", 10, 119))
    with pytest.raises(DemonstrationError, match="Ant-v2 file cannot serve: .* 111 columns"):
        ant.check_env(envs.make("Ant"))


@pytest.mark.parametrize("file_env", ["Hopper-v2", "Walker2d-v2"])
def test_a_column_count_that_does_not_fit_names_both_numbers(tmp_path, file_env):
    _, num_obs, num_actions, *_ = RELEASED[file_env]
    mixture = write_released(tmp_path, file_env, 4, num_obs + num_actions + 1)
    message = (
        f"rows have {num_obs + num_actions + 1} columns, but {file_env} rows \\[s, a\\] have "
        f"{num_obs} \\+ {num_actions} columns"
    )
    with pytest.raises(DemonstrationError, match=message):
        load_released(mixture)


# -- learning on the authors' files (C engine): where their files are present -------------

AUTHORS = authors_data()


def authors_file(task: str):
    """The authors' ``{task}_mixture.npy`` of conftest's ``authors_data``, or a skip."""
    path = AUTHORS / f"{task}_mixture.npy"
    if not path.exists():
        pytest.skip(f"the authors' {task} file is not in {AUTHORS}")
    return path


@pytest.mark.heavy
@pytest.mark.slow
def test_gail_learns_hopper_on_the_c_engine(tmp_path):
    """GAIL through the sweep's job (``jobs.sweep.run``, the sweep's Hopper-v4 settings: MuJoCo's
    C engine, 25 envs x 200 steps, 10 evaluation episodes every 50 iterations) on the authors'
    Hopper file, 2 seeds x 50 iterations (250,000 steps a seed). The random policy scores 18
    (Table 3), and what 250,000 steps of a broken discriminator's reward reach stays near it.
    Measured: 696 and 2,329 here (key 0, about 2 minutes on 2 cores beside other jobs); 457,
    349 and 465 at the same iteration in the 25 M grid. The bar: both seeds above 150."""
    from pngail_jax.jobs.sweep import run

    config = RunConfig(env="Hopper-v4", demos=str(authors_file("Hopper-v2")), methods=("gail",),
                       seeds=2, iterations=50)  # fmt: skip
    result = run(config, tmp_path / "run")
    final = [seed["final_return"] for seed in result.summary["methods"]["gail"]["per_seed"]]
    assert min(final) > 150, final


@pytest.mark.heavy
@pytest.mark.slow
def test_the_offline_family_learns_halfcheetah_on_the_c_engine(tmp_path):
    """The offline family on a MuJoCo task through the offline job, one program: BC on the
    expert rows (D_c's rows at confidence >= 0.5), BC on every row, DWBC and ISW-BC on the
    authors' HalfCheetah file, 2 seeds x 10,000 gradient steps, evaluated on the C engine (10
    episodes of 1,000 steps). Random scores -288 (Table 3). Measured here (key 0, 2026-12-07):
    BC (expert rows) 2,514 and 2,368; BC (every row) 1,154 and 1,158; DWBC 3,293 and 3,322
    (its default 5,000 discriminator updates, every 2nd step; 2,887 and 3,057 with 100, every
    100th); ISW-BC 1,851 and 2,687 (the committed record offline-halfcheetah, 5 seeds at
    50,000 steps: BC on the expert rows and DWBC 0.68 normalised). The bars: BC on the expert
    rows both seeds above 1,000; DWBC's and ISW-BC's mean over the seeds above 1,600, which BC
    on every row (the mixture's average, what a weighting gone flat gives) does not reach."""
    from pngail_jax.jobs.offline import OfflineRunConfig, run_offline

    methods = ("bc-expert", "bc-all", "dwbc", "iswbc")
    config = OfflineRunConfig(env="HalfCheetah-v4", demos=str(authors_file("HalfCheetah-v2")),
                              methods=methods, seeds=2, gradient_steps=10_000)  # fmt: skip
    summary = run_offline(config, tmp_path / "offline")
    final = {
        method: [seed["final_return"] for seed in summary["methods"][method]["per_seed"]]
        for method in methods
    }
    assert min(final["bc-expert"]) > 1000, final
    assert np.mean(final["dwbc"]) > 1600, final
    assert np.mean(final["iswbc"]) > 1600, final
    assert np.mean(final["bc-all"]) < 1600, final  # the bar tells weighting from none
