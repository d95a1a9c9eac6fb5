"""Per-environment run settings: the one table the command-line programs start from.

A ``RunSettings`` holds what differs between tasks but not between methods: the rollout
shape (parallel envs x unroll length, about 5,000 samples per iteration as in the paper),
the MJX solver caps, the physics engine of gymnasium's MuJoCo tasks, how often and on how
many episodes the deterministic policy is evaluated, and whether TRPO normalises
observations. The jobs (``pngail_jax.jobs``) and the programs (sweep, train_rl,
make_demos) use ``settings_for(env)`` unless a field is given;
``benchmarks/grid_throughput.py`` measures with them.

``REFERENCE_SETTINGS`` is the reference code's setting (25 envs x 200 steps, the task's own
solver, an evaluation of 32 episodes every 10 iterations, no observation normalisation).
Every departure from it in ``ENV_SETTINGS`` is justified by a learning measurement in
``docs/performance.md``.
"""

from __future__ import annotations

import dataclasses

from pngail_jax import envs
from pngail_jax.config import validation
from pngail_jax.config.learner import RolloutConfig


def _positive_int(name: str, value) -> int:
    """``value`` as a Python int (a NumPy integer is converted, so the settings stay JSON);
    ConfigError naming ``RunSettings.<name>`` unless it is an integer >= 1 (a bool is not)."""
    return validation.integer(name, value, 1, name=f"RunSettings.{name}")


def parse_solver(text: str) -> dict[str, int | None]:
    """``"own"`` (the task's own caps), ``"fast"`` (``envs.FAST_SOLVER``) or ``"I/L"``
    (I Newton and L line-search iterations) as ``RunSettings`` solver fields."""
    text = str(text).strip()
    if text == "own":
        return {"solver_iterations": None, "ls_iterations": None}
    if text == "fast":
        return dict(envs.FAST_SOLVER)
    parts = [part.strip() for part in text.split("/")]
    # isascii: str.isdigit also accepts digits int() cannot read ("²").
    if len(parts) == 2 and all(p.isascii() and p.isdigit() and int(p) > 0 for p in parts):
        return {"solver_iterations": int(parts[0]), "ls_iterations": int(parts[1])}
    raise ValueError(
        f"solver must be 'own', 'fast' or 'I/L' (positive Newton / line-search iteration "
        f"counts, e.g. 4/50), got {text!r}"
    )


def describe(settings: RunSettings, env: envs.Env | None = None) -> str:
    """One line for progress output and reports; with ``env``, the engine it runs on."""
    engine = getattr(env, "physics", None) or settings.physics
    physics = f"physics: {PHYSICS_NAMES[engine]}, " if engine else ""
    return (
        f"{settings.num_envs} envs x {settings.unroll_length} steps, {physics}solver: "
        f"{settings.solver_description}, evaluation: {settings.num_eval_episodes} episodes every "
        f"{settings.eval_every} iterations"
        + (", normalised observations" if settings.normalize_observations else "")
        + (", staggered starts" if settings.stagger_starts else "")
    )


@dataclasses.dataclass(frozen=True)
class RunSettings:
    """Static per-task settings. ``num_envs * unroll_length`` samples per policy iteration
    (TRPO or PPO)."""

    num_envs: int = 25
    unroll_length: int = 200
    # MJX Newton solver caps; None keeps the task's own (envs.make's options of that name).
    solver_iterations: int | None = None
    ls_iterations: int | None = None
    eval_every: int = 10
    num_eval_episodes: int = 32
    normalize_observations: bool = False
    # Each env's first episode cut at a random length, so that the parallel envs of a task
    # that never terminates are not in step (RolloutConfig.stagger_starts). Off in every row:
    # on HalfCheetah it learned no better than the lockstep (docs/performance.md).
    stagger_starts: bool = False
    # Engine of gymnasium's MuJoCo tasks (envs.PHYSICS); None: from the platform when the
    # environment is made (envs.default_physics), and the run's config.json records which ran.
    physics: str | None = None

    def __post_init__(self):
        # Frozen: counts are normalised to Python ints through object.__setattr__.
        for name in ("num_envs", "unroll_length", "eval_every", "num_eval_episodes"):
            object.__setattr__(self, name, _positive_int(name, getattr(self, name)))
        for name in ("solver_iterations", "ls_iterations"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _positive_int(name, getattr(self, name)))
        if self.physics is not None and self.physics not in envs.PHYSICS:
            validation.fail(
                "physics",
                f"must be one of {', '.join(envs.PHYSICS)} or None, got {self.physics!r}",
                name="RunSettings.physics",
            )
        for name in ("normalize_observations", "stagger_starts"):
            if not isinstance(getattr(self, name), bool):
                validation.fail(
                    name,
                    f"must be True or False, got {getattr(self, name)!r}",
                    name=f"RunSettings.{name}",
                )

    @property
    def samples_per_iteration(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def env_options(self) -> dict[str, int]:
        """Keyword options of ``envs.make`` (the solver caps that are set)."""
        options = {"solver_iterations": self.solver_iterations, "ls_iterations": self.ls_iterations}
        return {name: value for name, value in options.items() if value is not None}

    @property
    def solver_description(self) -> str:
        if not self.env_options:
            return "the task's own"
        return f"{self.solver_iterations} Newton / {self.ls_iterations} line-search iterations"

    def rollout_config(self, num_iterations: int, **options) -> RolloutConfig:
        """The ``RolloutConfig`` of a run of ``num_iterations`` with these settings; ``options``
        set its other fields (network sizes, GAE's form)."""
        return RolloutConfig(
            num_envs=self.num_envs,
            unroll_length=self.unroll_length,
            num_iterations=num_iterations,
            eval_every=self.eval_every,
            num_eval_episodes=self.num_eval_episodes,
            normalize_observations=self.normalize_observations,
            stagger_starts=self.stagger_starts,
            **options,
        )

    def replace(self, **overrides) -> RunSettings:
        """A copy with ``overrides`` applied; ``None`` values leave a field as it is (so
        command-line flags that were not given can be passed straight through)."""
        fields = {field.name for field in dataclasses.fields(self)}
        unknown = sorted(set(overrides) - fields)
        if unknown:
            raise ValueError(
                f"unknown run setting(s) {unknown}; known: {', '.join(sorted(fields))}"
            )
        given = {name: value for name, value in overrides.items() if value is not None}
        return dataclasses.replace(self, **given)


REFERENCE_SETTINGS = RunSettings()

PHYSICS_NAMES = {"c": "MuJoCo C engine (float64)", "mjx": "MJX", "warp": "MJX on MuJoCo Warp"}

# The MuJoCo tasks: the reference's 25 envs x 200 steps, the fast MJX solver (1 Newton / 4
# line-search iterations, Brax's own setting for Ant), and 10 evaluation episodes every 50
# iterations (the reference evaluates 5). The wide, short shape that suits a GPU (250 x 20,
# the same 5,000 samples) learned worse on Hopper, so it is an option, not the default.
# docs/performance.md gives the learning measurements behind each value.
MUJOCO_SETTINGS = RunSettings(
    solver_iterations=envs.FAST_SOLVER["solver_iterations"],
    ls_iterations=envs.FAST_SOLVER["ls_iterations"],
    eval_every=50,
    num_eval_episodes=10,
)

OWN_SOLVER_MUJOCO_SETTINGS = dataclasses.replace(
    MUJOCO_SETTINGS, solver_iterations=None, ls_iterations=None
)

ENV_SETTINGS: dict[str, RunSettings] = {
    "Pendulum-v1": REFERENCE_SETTINGS,
    # gymnasium's tasks keep gymnasium's solver, whichever engine: on the C engine it is what
    # makes the task equal gymnasium's.
    **{name: OWN_SOLVER_MUJOCO_SETTINGS for name in envs.GYM_TASKS},
    "Ant": MUJOCO_SETTINGS,
    # The fast solver makes HalfCheetah's physics diverge to NaN now and then
    # (docs/environments.md), which would poison a whole run's update: its own solver.
    "HalfCheetah": OWN_SOLVER_MUJOCO_SETTINGS,
    "Hopper": MUJOCO_SETTINGS,
    # With the fast solver TRPO learned worse on Swimmer (docs/performance.md): its own.
    "Swimmer": OWN_SOLVER_MUJOCO_SETTINGS,
    # Under random actions the fast solver ends Walker2d's episodes sooner, and its effect on
    # learning there is not measured yet: its own solver until it is.
    "Walker2d": OWN_SOLVER_MUJOCO_SETTINGS,
}


def settings_for(env_name: str, **overrides) -> RunSettings:
    """The table's settings of ``env_name`` with ``overrides`` (``None`` = keep) applied.

    An environment outside the table (one given to ``envs.register`` or named
    ``"package.module:factory"``) gets ``REFERENCE_SETTINGS``; a name ``envs.make`` does not
    know raises ValueError.
    """
    if env_name not in ENV_SETTINGS:
        envs.check_name(env_name)
    return ENV_SETTINGS.get(env_name, REFERENCE_SETTINGS).replace(**overrides)


def make_env(env_name: str, settings: RunSettings, cells: int = 1) -> envs.Env:
    """``envs.make(env_name)`` with the settings' solver caps (Pendulum takes none) and, for
    gymnasium's MuJoCo tasks, their physics engine; on MuJoCo Warp, sized for ``cells`` runs
    stepped together (``warp_batch``: each cell's training or evaluation envs, the wider)."""
    options = dict(settings.env_options)
    if env_name in envs.GYM_TASKS:
        options["physics"] = settings.physics
        if settings.physics == "warp":
            options["warp_batch"] = cells * max(settings.num_envs, settings.num_eval_episodes)
    elif settings.physics is not None:
        raise ValueError(
            f"RunSettings.physics: only gymnasium's MuJoCo tasks have a choice of engine, "
            f"not {env_name}"
        )
    return envs.make(env_name, **options)
