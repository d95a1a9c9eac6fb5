"""Grids of runs (methods x seeds x settings) as one compiled, optionally sharded, program.

A grid is a list of ``Cell``s. ``stack_cells`` turns it into stacked hyperparameters, method
specs and keys with one leading grid axis, for any ``MethodFamily`` (the family is passed in:
this module imports none); ``Grid`` compiles ``jit(vmap(trainer.init))`` and
``jit(vmap(trainer.run_blocks))`` over that axis and, when more than one device is given,
shards it over a one-axis ``Mesh`` (padding the grid to a multiple of the device count with
copies of its last cell, which are dropped from every result).

Cells never exchange data, so a NaN in one cell stays in that cell (``nonfinite_cells``
reports which). The same seed draws the same split, classifier and network initialisations
in every method and setting (common random numbers): methods differ only by their spec.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from pngail_jax.config.grid_axes import GRID_AXES
from pngail_jax.storage.checkpoint import is_key

GRID_AXIS = "grid"


class Trainer(Protocol):
    """What ``Grid`` needs of a trainer (``AdversarialTrainer`` and ``rl.PolicyTrainer`` have
    it): pure ``init(*cell_inputs, key) -> (state, metrics)`` and ``run_blocks(*cell_inputs,
    state, num_blocks=...) -> (state, metrics)``, where a block is ``eval_every`` iterations
    ending in an evaluation, and ``policy_state(state)``, the learner state of its policy."""

    init: Callable[..., Any]
    run_blocks: Callable[..., Any]
    policy_state: Callable[[Any], Any]

    @property
    def eval_every(self) -> int: ...


# The per-cell axes (HYPERPARAM_AXES, METHOD_AXES, GRID_AXES) are the config's grid part's,
# plain data: pngail_jax.config.grid_axes.


@dataclasses.dataclass(frozen=True)
class Cell:
    """One run of a grid: a method, a seed and a setting (label ratio, noise and the value of
    every other grid axis, ``axes``: ``((field, value), ...)`` from ``GRID_AXES``)."""

    method: str
    seed: int
    label_ratio: float = 0.2
    noise_std: float = 0.0
    axes: tuple[tuple[str, float], ...] = ()

    @property
    def setting(self) -> str:
        extra = "".join(f",{field}={value:g}" for field, value in self.axes)
        return f"label_ratio={self.label_ratio:g},noise={self.noise_std:g}{extra}"


def make_cells(
    methods: Sequence[str],
    num_seeds: int,
    label_ratios: Sequence[float] = (0.2,),
    noise_stds: Sequence[float] = (0.0,),
    axes: Sequence[tuple[str, Sequence[float]]] = (),
) -> list[Cell]:
    """Every combination, ordered setting-major (label ratio, noise, then each of ``axes``,
    ``(field, values)`` pairs of ``GRID_AXES``, in order), then method, then seed."""
    unknown = [field for field, _ in axes if field not in GRID_AXES]
    if unknown:
        raise ValueError(f"grid axes must be among {GRID_AXES}, got {unknown}")
    fields = [field for field, _ in axes]
    return [
        Cell(method, seed, label_ratio, noise_std, tuple(zip(fields, values, strict=True)))
        for label_ratio in label_ratios
        for noise_std in noise_stds
        for values in itertools.product(*(values for _, values in axes))
        for method in methods
        for seed in range(num_seeds)
    ]


@dataclasses.dataclass(frozen=True)
class MethodFamily:
    """What a grid and a job need of a method family (adversarial, offline, the next one), as
    plain functions, so ``stack_cells`` and ``Grid`` never name a family's modules: a job
    passes its family in (``pngail_jax.adversarial.family.ADVERSARIAL``,
    ``pngail_jax.offline.family.OFFLINE``).

    - ``name``: the family's name ("adversarial", "offline");
    - ``method_names``: its built-in method names (``check_method`` may accept more: a
      registered name, ``package.module:preset``);
    - ``check_method(name) -> name``: the name, resolved and checked; a one-line ValueError
      naming the known ones for an unknown name;
    - ``spec(name, **overrides)``: the method as data, a pytree of float[] leaves (the
      trainer's spec; ``overrides`` set its fields; an unknown field is a ValueError);
    - ``spec_axes`` and ``hyperparam_axes``: the grid axes (``Cell.axes`` fields) that set a
      spec field or a hyperparameter; a cell with any other axis is refused;
    - ``hyperparams(cell, **values)``: the cell's hyperparameters, a pytree of scalar
      leaves (float[], a learner's flag bool[]), from its label ratio and noise and
      ``values`` (shared keywords and its ``hyperparam_axes``);
    - ``parts(methods)``: the parts of the trainer that ``methods`` need compiled (the
      adversarial phases, the offline components), in the family's order;
    - ``program_groups(methods)``: ``methods`` grouped into the programs a grid compiles, in
      order of first appearance (one program for the adversarial family);
    - ``trainer``: the trainer class (``Trainer`` interface), whose cell inputs are
      ``(hyperparams, spec)`` and the key.
    """

    name: str
    method_names: tuple[str, ...]
    check_method: Callable[[str], str]
    spec: Callable[..., Any]
    spec_axes: tuple[str, ...]
    hyperparam_axes: tuple[str, ...]
    hyperparams: Callable[..., Any]
    parts: Callable[[Sequence[str]], tuple[str, ...]]
    program_groups: Callable[[Sequence[str]], list[tuple[str, ...]]]
    trainer: type


def stack_cells(
    cells: Sequence[Cell],
    key: jax.Array,
    method_overrides: dict[str, float] | None = None,
    *,
    family: MethodFamily,
    **hyperparams,
) -> tuple[Any, Any, jax.Array]:
    """Stacked ``(hyperparams, specs, keys)`` of ``family``'s cells with a leading axis of
    ``len(cells)``: the inputs of ``Grid(trainer)`` for a trainer of that family.

    ``hyperparams`` are keywords of ``family.hyperparams`` shared by every cell, and
    ``method_overrides`` spec fields; a cell's ``axes`` override either (those of
    ``family.spec_axes`` the spec, of ``family.hyperparam_axes`` the hyperparameters). Each
    cell's key is ``fold_in(key, cell.seed)``.
    """
    if not cells:
        raise ValueError("a grid needs at least one cell")
    overrides = method_overrides or {}
    specs, cell_hyperparams = [], []
    for cell in cells:
        axes = dict(cell.axes)
        unknown = sorted(set(axes) - set(family.spec_axes) - set(family.hyperparam_axes))
        if unknown:
            raise ValueError(f"the {family.name} family's cells take no grid axis {unknown}")
        method_values = {f: v for f, v in axes.items() if f in family.spec_axes}
        specs.append(family.spec(cell.method, **{**overrides, **method_values}))
        values = {**hyperparams, **{f: v for f, v in axes.items() if f in family.hyperparam_axes}}
        cell_hyperparams.append(family.hyperparams(cell, **values))
    keys = jnp.stack([jax.random.fold_in(key, cell.seed) for cell in cells])
    return stack(cell_hyperparams), stack(specs), keys


def stack(trees):
    """Stacks equal-structure pytrees (specs, hyperparameters) along a new leading axis."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)


def _pad(tree, size: int):
    def pad(x):
        extra = size - x.shape[0]
        return x if extra == 0 else jnp.concatenate([x, jnp.repeat(x[-1:], extra, axis=0)])

    return jax.tree.map(pad, tree)


def _put_global(tree, sharding: NamedSharding):
    """``device_put`` that also works when the mesh spans several processes (multi-host,
    after ``jax.distributed.initialize``): every process holds the whole host value and
    contributes the shards of its own devices."""
    if sharding.is_fully_addressable:
        return jax.device_put(tree, sharding)

    def put(x):
        if is_key(x):
            return jax.random.wrap_key_data(put(jax.random.key_data(x)))
        host = np.asarray(x)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(put, tree)


class Grid:
    """Compiled init and chunk programs for stacked cells, sharded over ``devices``.

    ``trainer`` is any object with the trainer interface (``AdversarialTrainer``,
    ``pngail_jax.rl.PolicyTrainer``); ``inputs`` are the arguments of its ``init``, each stacked
    with a leading grid axis, the keys last: ``(hyperparams, specs, keys)`` from
    ``stack_cells`` for adversarial training, ``(hyperparams, keys)`` for TRPO.

    ``run_chunk(state)`` advances every cell by ``blocks_per_chunk * eval_every`` iterations;
    ``unpad(tree)`` drops padding cells from a host copy of any grid-leading pytree.
    """

    def __init__(
        self,
        trainer: Trainer,
        inputs: tuple,
        blocks_per_chunk: int,
        devices: Sequence[jax.Device] | None = None,
    ):
        self.num_cells = inputs[-1].shape[0]
        devices = list(jax.devices() if devices is None else devices)
        self.num_devices = len(devices)
        self.num_padded = math.ceil(self.num_cells / self.num_devices) * self.num_devices
        self.blocks_per_chunk = blocks_per_chunk
        self.iterations_per_chunk = blocks_per_chunk * trainer.eval_every
        inputs = _pad(tuple(inputs), self.num_padded)
        if self.num_devices > 1:
            mesh = jax.make_mesh(
                (self.num_devices,),
                (GRID_AXIS,),
                axis_types=(jax.sharding.AxisType.Auto,),
                devices=devices,
            )
            self.sharding = NamedSharding(mesh, PartitionSpec(GRID_AXIS))
            inputs = _put_global(inputs, self.sharding)
        else:
            self.sharding = None
            inputs = jax.device_put(inputs, devices[0])
        self.devices = devices
        self.cell_inputs, self.keys = tuple(inputs[:-1]), inputs[-1]
        jit = functools.partial(jax.jit, out_shardings=self.sharding)
        init = jit(jax.vmap(trainer.init))
        start = time.perf_counter()
        state_shape, _ = jax.eval_shape(init, *inputs)
        self._state_shape = state_shape
        chunk = jax.vmap(functools.partial(trainer.run_blocks, num_blocks=blocks_per_chunk))
        state_index = len(self.cell_inputs)
        lowered = (
            init.lower(*inputs),
            jit(chunk, donate_argnums=(state_index,)).lower(
                *self.cell_inputs, self._with_sharding(state_shape)
            ),
        )
        (init_program, init_seconds), (chunk_program, chunk_seconds) = compile_side_by_side(lowered)
        self.init_program, self.chunk_program = init_program, chunk_program
        # Each program's own compile (XLA's, or the persistent cache's read), and the wall
        # time of both with their tracing and lowering: on more than one core the two
        # compiles overlap, so it is less than their sum.
        self.init_compile_seconds, self.chunk_compile_seconds = init_seconds, chunk_seconds
        self.compile_seconds = time.perf_counter() - start

    def _with_sharding(self, state_shape):
        if self.sharding is None:
            return state_shape
        return jax.tree.map(
            lambda s: jax.ShapeDtypeStruct(s.shape, s.dtype, sharding=self.sharding), state_shape
        )

    def state_shape(self):
        """The shapes and dtypes (``jax.ShapeDtypeStruct``) of the real cells' state, without
        running the init: what a checkpoint is restored into."""
        return jax.tree.map(
            lambda s: jax.ShapeDtypeStruct((self.num_cells, *s.shape[1:]), s.dtype),
            self._state_shape,
        )

    def init(self):
        """``(state, init_metrics)`` of every cell (device arrays): for adversarial training,
        the splits, classifier phase and initial networks."""
        return self.init_program(*self.cell_inputs, self.keys)

    def run_chunk(self, state):
        """The next chunk. ``state`` is donated (do not reuse it); metrics float[G, I]."""
        return self.chunk_program(*self.cell_inputs, state)

    def place(self, state):
        """Pads an unpadded state (e.g. restored from a checkpoint, possibly written with a
        different device count) and puts it where ``run_chunk`` expects it."""
        state = _pad(state, self.num_padded)
        if self.sharding is None:
            return jax.device_put(state, self.devices[0])
        return _put_global(state, self.sharding)

    def unpad(self, tree):
        """The real cells of any grid-leading pytree (host or device arrays)."""
        return jax.tree.map(lambda x: x[: self.num_cells], tree)

    def fetch(self, tree):
        """Host copy of the real cells of a grid-leading pytree of device arrays, gathered
        from every process when the mesh spans several (then every process must call it)."""
        if self.sharding is not None and not self.sharding.is_fully_addressable:
            from jax.experimental import multihost_utils

            keys = jax.tree.map(is_key, tree)  # gathered as their raw key data
            data = jax.tree.map(lambda x, k: jax.random.key_data(x) if k else x, tree, keys)
            data = multihost_utils.process_allgather(data, tiled=True)
            tree = jax.tree.map(lambda x, k: jax.random.wrap_key_data(x) if k else x, data, keys)
        return self.unpad(jax.device_get(tree))


# The thread that compiles every program of ``compile_side_by_side`` but the last (the
# cold-start benchmark tells the programs' compile events apart by it).
COMPILE_THREAD = "grid-compile"


def compile_side_by_side(lowered: Sequence[Any]) -> list[tuple[Any, float]]:
    """``(compiled, seconds)`` of each of the ``lowered`` programs (``jax.stages.Lowered``),
    the last compiled in this thread and each other in a thread of its own at the same
    time: XLA's compile (or the persistent cache's read) releases the GIL, so on a second
    core the shorter compiles cost no wall time. ``seconds`` is each one's own compile.
    On the CPU only: a GPU's compile times candidate kernels (autotuning), which two
    compiles at once would time against each other, so there they run one after another."""

    def timed(program):
        start = time.perf_counter()
        compiled = program.compile()
        return compiled, time.perf_counter() - start

    *others, last = lowered
    if not others or jax.default_backend() != "cpu":
        return [timed(program) for program in lowered]
    threads = concurrent.futures.ThreadPoolExecutor(len(others), COMPILE_THREAD)
    with threads as pool:
        futures = [pool.submit(timed, program) for program in others]
        compiled_last = timed(last)
        return [future.result() for future in futures] + [compiled_last]


def nonfinite_cells(metrics: dict[str, np.ndarray], eval_every: int) -> np.ndarray:
    """Indices of cells that went non-finite: a NaN or inf evaluated return or discriminator
    loss, or any rollout step that applied a NaN or inf action (a nonzero
    ``rollout/nonfinite_actions``, ``pngail_jax.rl.rollout.rollout_metrics``).

    metrics float[G, I] from whole chunks (which start at multiples of ``eval_every``), so
    ``eval/return`` is defined at every ``eval_every``-th column and NaN by design elsewhere.
    Of the other two, those a trainer does not produce are skipped (TRPO alone has no
    ``disc/loss``; metrics saved before the action count existed have no count).
    """
    evaluations = np.asarray(metrics["eval/return"])[:, eval_every - 1 :: eval_every]
    bad = ~np.isfinite(evaluations).all(axis=1)
    if "disc/loss" in metrics:
        bad |= ~np.isfinite(np.asarray(metrics["disc/loss"])).all(axis=1)
    if "rollout/nonfinite_actions" in metrics:
        bad |= (np.asarray(metrics["rollout/nonfinite_actions"]) != 0).any(axis=1)
    return np.flatnonzero(bad)
