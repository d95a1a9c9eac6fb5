"""``RunConfig``: everything that defines a sweep, frozen and validated, saved as JSON.

The command line (``python -m experiments.sweep``) only fills one in; Python users build it
directly (``RunConfig(env="Hopper", methods=("gail", "pngail"))``) or from a preset
(``RunConfig.preset("paper", demos="...")``). ``to_json`` / ``from_json`` round-trip it, so a
saved ``config.json`` starts a new run (``--config FILE``) or continues one (``--resume DIR``).
``provenance()`` adds what a saved run should remember of where it ran.
"""

from __future__ import annotations

import dataclasses
import json
import math
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from pngail_jax.confidence import ClassifierConfig
from pngail_jax.methods import METHOD_NAMES, PRESETS
from pngail_jax.settings import RunSettings, settings_for
from pngail_jax.tracking import BACKENDS as LOG_BACKENDS
from pngail_jax.train import AdversarialConfig

FISHER_FORMS = ("gauss_newton", "hessian")
# BSC's clip per task where the paper departs from 0.01 (appendix C.2: 0.05 on Walker2d).
TASK_BSC_EPS = {"Walker2d": 0.05}


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """One sweep: a grid of methods x seeds x label ratios x noise levels on one environment.

    The defaults are the smoke scale (a few minutes on a 2-core CPU); ``settings`` defaults to
    the environment's row of ``pngail_jax.settings.ENV_SETTINGS``.
    """

    env: str = "Pendulum-v1"
    methods: tuple[str, ...] = METHOD_NAMES
    seeds: int = 3
    iterations: int = 300
    label_ratios: tuple[float, ...] = (0.2,)
    noise_stds: tuple[float, ...] = (0.0,)
    seed: int = 0  # base PRNG seed; cell keys are fold_in(key(seed), cell seed)
    # Demonstrations: a *_mixture.npy (authors' layout), an .npz, or "minari:<dataset id>";
    # None: made by experiments.make_demos and cached.
    demos: str | None = None
    conf: str | None = None  # confidence file (default: the mixture's sibling)
    confidence_field: str | None = None  # Minari: the per-episode field holding confidences
    action_scale: float = 1.0  # multiplies stored actions (2 for the authors' Pendulum set)
    num_demos: int | None = None  # rows per split, n_c + n_u (None: every row)
    chunk_iterations: int = 50  # iterations per compiled chunk (progress + checkpoint)
    settings: RunSettings | None = None
    classifier: ClassifierConfig = ClassifierConfig()
    bsc_eps: float | None = None  # None: the task's (TASK_BSC_EPS, else 0.01)
    fisher: str = "gauss_newton"
    fisher_subsample: int = 1
    discriminator_hidden_sizes: tuple[int, ...] = (100, 100)
    cpu_devices: int | None = None  # split a CPU into this many XLA devices
    log: tuple[str, ...] = ()  # "tensorboard" and/or "wandb"
    preset_name: str | None = None  # the preset this config started from, for the record

    def __post_init__(self):
        # Frozen: fields are normalised through object.__setattr__ (lists from JSON -> tuples).
        for name in ("methods", "label_ratios", "noise_stds", "log", "discriminator_hidden_sizes"):
            value = getattr(self, name)
            value = tuple(value) if isinstance(value, list | tuple) else (value,)
            object.__setattr__(self, name, value)
        if self.settings is None:  # the environment's row (raises for an unknown environment)
            object.__setattr__(self, "settings", settings_for(self.env))
        self._validate()

    def _validate(self) -> None:
        def fail(message: str):
            raise ValueError(message)

        unknown = [name for name in self.methods if name not in PRESETS]
        if unknown or not self.methods:
            fail(f"unknown method(s) {unknown}; available: {', '.join(METHOD_NAMES)}")
        if len(set(self.methods)) != len(self.methods):
            fail(f"methods must not repeat, got {list(self.methods)}")
        for name in ("seeds", "iterations", "chunk_iterations", "fisher_subsample"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                fail(f"{name} must be a positive integer, got {value!r}")
        if self.cpu_devices is not None and (
            isinstance(self.cpu_devices, bool)
            or not isinstance(self.cpu_devices, int)
            or self.cpu_devices < 1
        ):
            fail(f"cpu_devices must be a positive integer, got {self.cpu_devices!r}")
        if self.num_demos is not None and (
            not isinstance(self.num_demos, int) or self.num_demos < 2
        ):
            fail(f"num_demos must be an integer >= 2, got {self.num_demos!r}")
        if not all(_finite(r) and 0 < r < 1 for r in self.label_ratios) or not self.label_ratios:
            fail(f"label ratios must lie in (0, 1), got {list(self.label_ratios)}")
        if not all(_finite(s) and s >= 0 for s in self.noise_stds) or not self.noise_stds:
            fail(f"noise stds must be finite and >= 0, got {list(self.noise_stds)}")
        if not (_finite(self.action_scale) and self.action_scale > 0):
            fail(f"action_scale must be finite and positive, got {self.action_scale!r}")
        if self.bsc_eps is not None and not (_finite(self.bsc_eps) and 0 < self.bsc_eps < 0.5):
            fail(f"bsc_eps must lie in (0, 0.5), got {self.bsc_eps!r}")
        if self.fisher not in FISHER_FORMS:
            fail(f"fisher must be one of {FISHER_FORMS}, got {self.fisher!r}")
        bad_backends = [name for name in self.log if name not in LOG_BACKENDS]
        if bad_backends:
            fail(f"unknown log backend(s) {bad_backends}; available: {', '.join(LOG_BACKENDS)}")
        if self.iterations % self.settings.eval_every:
            fail(
                f"iterations ({self.iterations}) must be a multiple of the evaluation interval "
                f"({self.settings.eval_every}; set it with --eval-every)"
            )
        if self.conf is not None and self.demos is None:
            fail("a confidence file needs demos (made demonstrations carry their own)")
        is_minari = self.demos is not None and self.demos.startswith("minari:")
        if self.confidence_field is not None and not is_minari:
            fail("confidence_field reads a Minari dataset's episode metadata: demos minari:<id>")
        if (
            self.demos is not None
            and self.demos.endswith(".npz")
            and (self.conf is not None or self.action_scale != 1.0)
        ):
            fail("an .npz set carries its confidences and units: no conf or action_scale")

    @classmethod
    def preset(cls, name: str, **overrides) -> RunConfig:
        """The named preset (``PRESETS_BY_NAME``) with ``overrides``."""
        if name not in PRESETS_BY_NAME:
            raise ValueError(f"unknown preset {name!r}; available: {', '.join(PRESETS_BY_NAME)}")
        return cls(**{**PRESETS_BY_NAME[name], "preset_name": name, **overrides})

    def replace(self, **overrides) -> RunConfig:
        """A validated copy with ``overrides``. A new environment gets its own settings row
        unless ``settings`` is given too."""
        if overrides.get("env", self.env) != self.env and "settings" not in overrides:
            overrides["settings"] = None
        return dataclasses.replace(self, **overrides)

    @property
    def task_bsc_eps(self) -> float:
        return self.bsc_eps if self.bsc_eps is not None else TASK_BSC_EPS.get(self.env, 0.01)

    @property
    def num_settings(self) -> int:
        return len(self.label_ratios) * len(self.noise_stds)

    def adversarial_config(self) -> AdversarialConfig:
        """The static configuration of the trainer this run builds."""
        return AdversarialConfig(
            trpo=self.settings.trpo_config(
                self.iterations, fisher=self.fisher, fisher_subsample=self.fisher_subsample
            ),
            classifier=self.classifier,
            num_demos=self.num_demos,
            discriminator_hidden_sizes=self.discriminator_hidden_sizes,
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        """The config of ``to_dict`` (or of a ``config.json``: its other keys, such as
        ``resolved`` and ``provenance``, are ignored)."""
        data = upgrade_saved_config(data)
        fields = {field.name for field in dataclasses.fields(cls)}
        values = {key: value for key, value in data.items() if key in fields}
        if values.get("settings") is not None:
            values["settings"] = RunSettings(**values["settings"])
        if values.get("classifier") is not None:
            classifier = dict(values["classifier"])
            if "hidden_sizes" in classifier:
                classifier["hidden_sizes"] = tuple(classifier["hidden_sizes"])
            values["classifier"] = ClassifierConfig(**classifier)
        return cls(**values)

    @classmethod
    def from_json(cls, path: str | Path) -> RunConfig:
        path = Path(path)
        try:
            data = json.loads(path.read_text())
            return cls.from_dict(data)
        except (OSError, json.JSONDecodeError, TypeError) as error:
            raise ValueError(f"{path}: not a run config ({error})") from None
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None


PRESETS_BY_NAME: dict[str, dict[str, Any]] = {
    # A few minutes on a 2-core CPU (the command line's default).
    "smoke": {"iterations": 300, "seeds": 3, "chunk_iterations": 50},
    # The paper's budget: 5,000 TRPO iterations, 5 seeds (a GPU run).
    "paper": {"iterations": 5_000, "seeds": 5, "chunk_iterations": 250},
}


def upgrade_saved_config(data: dict[str, Any]) -> dict[str, Any]:
    """A config.json written before ``RunConfig`` (flat keys) in today's layout; today's
    unchanged."""
    if "classifier_steps" not in data:  # the old layout's mark
        return data
    from pngail_jax.settings import REFERENCE_SETTINGS

    settings = data.get("settings") or dataclasses.asdict(
        REFERENCE_SETTINGS.replace(
            num_envs=data["num_envs"],
            unroll_length=data["unroll_length"],
            eval_every=data["eval_every"],
        )
    )
    kept = (
        "env methods seeds iterations label_ratios noise_stds seed action_scale num_demos "
        "chunk_iterations fisher fisher_subsample cpu_devices demos conf"
    ).split()
    return {
        **{key: data[key] for key in kept if key in data},
        "settings": settings,
        "classifier": {"num_steps": data["classifier_steps"]},
        "resolved": {"demos_path": data["demos"]},
        "provenance": {
            key: data[key] for key in ("platform", "device_count", "local_device_count")
        },
    }


def _finite(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def provenance(argv: list[str] | None = None) -> dict[str, Any]:
    """Where and with what a run ran: versions, git commit, devices, the command line."""
    import jax

    def version(package: str) -> str | None:
        try:
            return metadata.version(package)
        except metadata.PackageNotFoundError:
            return None

    devices = jax.devices()
    return {
        "pngail_jax_version": version("pngail-jax"),
        "git_commit": _git_commit(),
        "python": platform.python_version(),
        "libraries": {
            name: version(name)
            for name in ("jax", "jaxlib", "flax", "optax", "brax", "mujoco", "mujoco-mjx")
        },
        "platform": devices[0].platform,
        "device_kind": devices[0].device_kind,
        "device_count": len(devices),
        "local_device_count": len(jax.local_devices()),
        "process_count": jax.process_count(),
        "command_line": [Path(sys.argv[0]).name, *(sys.argv[1:] if argv is None else argv)],
    }


def _git_commit() -> str | None:
    """The checkout's commit (with ``+dirty`` when files differ), or None outside git."""
    root = Path(__file__).resolve().parent.parent
    try:
        toplevel = subprocess.run(
            ["git", "rev-parse", "--show-toplevel"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        )
        if toplevel.returncode != 0 or Path(toplevel.stdout.strip()).resolve() != root:
            return None  # an installed copy, possibly inside another project's checkout
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        )
        if commit.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        )
        return commit.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None
