"""Demonstration inputs you can trust: every bad file or flag ends in a one-line error naming
the file (or flag) and the problem, or loads correctly; the ``labelled`` mask is honoured."""

import io
import json
import types
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import authors_data
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pngail_jax import envs
from pngail_jax.adversarial import trainer as adversarial
from pngail_jax.demos import (
    ACTION_BOUND_MULTIPLE,
    DemonstrationError,
    Demonstrations,
    load_demonstrations,
    load_npz,
    load_released,
    make_split,
    save_npz,
)

AUTHORS_PENDULUM = authors_data()
needs_authors_pendulum = pytest.mark.skipif(
    not (AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy").exists(),
    reason=f"the authors' Pendulum set is not at {AUTHORS_PENDULUM}",
)
HYPOTHESIS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,  # the same draws on every machine: a new draw never breaks CI
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
# A value silently turned into inf on the way in (e.g. float64 beyond float32) warns: fail.
no_runtime_warnings = pytest.mark.filterwarnings("error::RuntimeWarning")


def npy_bytes(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array), allow_pickle=True)
    return buffer.getvalue()


def npz_bytes(**arrays) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


GOOD_ROWS = np.arange(8, dtype=np.float32).reshape(2, 4) / 8  # Pendulum: 3 obs + 1 action
GOOD_CONF = np.array([[1.0], [0.5]])
GOOD_NPY = npy_bytes(GOOD_ROWS)
GOOD_NPZ = npz_bytes(
    observations=GOOD_ROWS[:, :3],
    actions=GOOD_ROWS[:, 3:],
    confidence=GOOD_CONF[:, 0],
    metadata_json=np.asarray(json.dumps({"env": "Pendulum-v1"})),
    format_version=np.asarray(1),
)


def write_released(directory: Path, rows, conf=GOOD_CONF, env_name="Pendulum-v1") -> Path:
    """``{env}_mixture.npy`` (bytes or an array) and its ``_conf.npy`` in ``directory``."""
    mixture = directory / f"{env_name}_mixture.npy"
    for path, content in ((mixture, rows), (directory / f"{env_name}_mixture_conf.npy", conf)):
        path.write_bytes(content if isinstance(content, bytes) else npy_bytes(content))
    return mixture


def stand_in_env(name, observation_size, action_size, bound=1.0):
    """What ``Demonstrations.check_env`` reads of an environment, without building one."""
    return types.SimpleNamespace(
        name=name,
        observation_size=observation_size,
        action_size=action_size,
        action_low=np.full(action_size, -bound, np.float32),
        action_high=np.full(action_size, bound, np.float32),
    )


# --- one explicit test per kind of bad file ------------------------------------------------


def _corrupt_header(data: bytes) -> bytes:
    header_start = 10  # magic (6) + version (2) + header length (2)
    return data[:header_start] + b"{'descr': <f4, garbage" + data[header_start + 22 :]


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", r"is empty \(0 bytes\)"),
        (GOOD_NPY[:-5], r"is truncated: expected 32 bytes of data for shape \(2, 4\) float32, "),
        (bytes(range(7, 250, 3)), r"is not a NumPy \.npy file \(bad header\)"),
        (_corrupt_header(GOOD_NPY), r"is not a NumPy \.npy file \(corrupt header\)"),
        (npy_bytes(np.array([{"a": 1}, None])), r"holds pickled Python objects, which are not"),
        (npy_bytes(np.array([["a", "b", "c", "d"]])), r"holds strings \(dtype <U1\), expected"),
        (GOOD_NPZ, r"is a \.npz archive, expected a \.npy file"),
    ],
    ids=["empty", "truncated", "random-bytes", "corrupt-header", "pickled", "strings", "npz"],
)
@pytest.mark.parametrize("role", ["mixture file", "confidence file"])
def test_bad_npy_files_name_the_file_its_role_and_the_problem(tmp_path, content, problem, role):
    mixture = tmp_path / "Pendulum-v1_mixture.npy"
    conf = tmp_path / "Pendulum-v1_mixture_conf.npy"
    if role == "mixture file":
        write_released(tmp_path, content)
    else:
        write_released(tmp_path, GOOD_ROWS, content)
    bad = mixture if role == "mixture file" else conf
    with pytest.raises(DemonstrationError, match=f"^{role} {bad}: {problem}") as error:
        load_demonstrations(mixture)
    assert "\n" not in str(error.value)


def _npz_with_member(name: str, member: bytes) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("format_version.npy", npy_bytes(np.asarray(1)))
        archive.writestr("observations.npy", npy_bytes(GOOD_ROWS[:, :3]))
        archive.writestr(f"{name}.npy", member)
    return buffer.getvalue()


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", r"is empty \(0 bytes\)"),
        (GOOD_NPZ[:-40], r"not a readable NumPy \.npz archive, truncated or corrupt"),
        (bytes(range(7, 250, 3)), r"not a NumPy \.npz archive \(not a zip archive\)"),
        (GOOD_NPY, r"not a NumPy \.npz archive \(a \.npy file\)"),
        (npz_bytes(observations=GOOD_ROWS, format_version=np.asarray(1)), r"has no array 'act"),
        (_npz_with_member("actions", npy_bytes(np.array([None]))), r"array 'actions' holds pick"),
        (_npz_with_member("actions", GOOD_NPY[:-5]), r"array 'actions' is truncated: expected"),
        (_npz_with_member("actions", b"\x93NUMPY\x01\x00junk"), r"array 'actions' is not a Num"),
        (_npz_with_member("actions", npy_bytes(np.array([["x"]]))), r"array 'actions' holds strin"),
        (npz_bytes(observations=GOOD_ROWS), r"has no array 'format_version' \(not written by"),
        (npz_bytes(format_version=np.asarray([1, 2])), r"format_version must be one integer"),
    ],
    ids=[
        "empty",
        "truncated",
        "random-bytes",
        "npy",
        "missing-array",
        "pickled",
        "truncated-member",
        "corrupt-member",
        "strings",
        "no-version",
        "version-array",
    ],
)
def test_bad_npz_files_name_the_file_and_the_problem(tmp_path, content, problem):
    path = tmp_path / "demos.npz"
    path.write_bytes(content)
    with pytest.raises(DemonstrationError, match=f"^demonstrations .npz {path}: {problem}"):
        load_demonstrations(path)


def test_a_missing_confidence_file_is_named(tmp_path):
    mixture = write_released(tmp_path, GOOD_ROWS)
    with pytest.raises(FileNotFoundError, match=f"confidence file not found: {tmp_path}/c.npy"):
        load_released(mixture, tmp_path / "c.npy")
    with pytest.raises(DemonstrationError, match=f"confidence file {tmp_path}: is a directory"):
        load_released(mixture, tmp_path)


def test_released_rows_must_hold_the_known_environments_action_columns(tmp_path):
    mixture = write_released(tmp_path, np.zeros((2, 5), np.float32))
    message = f"mixture file {mixture}: rows have 5 columns, but Pendulum-v1 rows .* 3 \\+ 1 col"
    with pytest.raises(DemonstrationError, match=message):
        load_released(mixture)
    # An explicit observation size is the user's layout: 3 + 2 is then allowed.
    assert load_released(mixture, observation_size=3).actions.shape == (2, 2)


def test_a_mixture_file_without_rows_is_named_before_its_confidence_is_read(tmp_path):
    """Hypothesis found it: empty rows and confidences raised numpy's 'zero-size array to
    reduction operation minimum' from the confidence check."""
    mixture = write_released(tmp_path, np.zeros((0, 4), np.float16), np.zeros(0, np.float16))
    with pytest.raises(DemonstrationError, match=rf"^mixture file {mixture}: has no rows \(shape"):
        load_released(mixture)


@pytest.mark.parametrize(
    ("conf", "problem"),
    [
        (np.ones((3, 1)), r"has 3 rows, but mixture file .*Pendulum-v1_mixture.npy has 2"),
        (np.ones((2, 2)), r"expected shape \(N,\) or \(N, 1\), one confidence per row"),
        (np.array([[1.0], [1.5]]), r"confidence must lie in \[0, 1\], got values in \[1, 1.5\]"),
        (np.array([np.nan, 1.0]), r"confidence contains NaN or infinite values"),
    ],
    ids=["rows", "shape", "range", "nan"],
)
def test_confidence_file_errors_name_the_confidence_file(tmp_path, conf, problem):
    mixture = write_released(tmp_path, GOOD_ROWS, conf)
    conf_path = tmp_path / "Pendulum-v1_mixture_conf.npy"
    with pytest.raises(DemonstrationError, match=f"^confidence file {conf_path}: {problem}"):
        load_released(mixture)


def test_non_finite_rows_name_the_mixture_file(tmp_path):
    rows = GOOD_ROWS.copy()
    rows[1, 3] = np.inf
    mixture = write_released(tmp_path, rows)
    message = rf"^mixture file {mixture}: actions contains NaN or infinite values \(first at row 1,"
    with pytest.raises(DemonstrationError, match=message):
        load_released(mixture)
    with pytest.raises(DemonstrationError, match="action_scale must be positive and finite"):
        load_released(mixture, action_scale=float("inf"))
    huge = write_released(tmp_path, np.full((2, 4), 1e300))  # finite, but not in float32
    message = rf"^mixture file {huge}: observations .* \(first at row 0, column 0: 1e\+300, beyond"
    with pytest.raises(DemonstrationError, match=message):
        load_released(huge)


@pytest.mark.parametrize(
    ("returns", "valid"),
    [((-100.0, -100.0), False), ((float("nan"), 1.0), False), ((0.0, float("inf")), False),
     (("low", 1.0), False), ((-1200.0, -117.0), True)],
)  # fmt: skip
def test_npz_random_and_optimal_returns_must_normalise(tmp_path, returns, valid):
    path = tmp_path / "demos.npz"
    metadata = {"random_return": returns[0], "optimal_return": returns[1]}
    save_npz(path, Demonstrations(GOOD_ROWS[:, :3], GOOD_ROWS[:, 3:], metadata=metadata))
    if valid:
        assert load_npz(path).metadata == metadata
        return
    message = f"^demonstrations .npz {path}: metadata random_return .* two different finite"
    with pytest.raises(DemonstrationError, match=message):
        load_npz(path)


def test_an_optimal_return_below_the_random_one_loads_with_a_warning(tmp_path):
    """make_demos at a tiny budget writes such sets (and warns): usable, said again on load."""
    path = tmp_path / "demos.npz"
    metadata = {"random_return": 5.0, "optimal_return": 1.0}
    save_npz(path, Demonstrations(GOOD_ROWS[:, :3], GOOD_ROWS[:, 3:], metadata=metadata))
    with pytest.warns(UserWarning, match=f"{path}: its optimal_return 1.0 is below"):
        assert load_npz(path).metadata == metadata


# --- actions and bounds ------------------------------------------------------------------


def test_actions_a_little_outside_the_bounds_load_as_in_the_authors_mujoco_files(tmp_path):
    """Shaped like the authors' Hopper-v2 file: 11 obs + 3 unclipped actions, ~40% of entries
    outside [-1, 1], up to 6.65."""
    rng = np.random.default_rng(0)
    actions = np.clip(rng.normal(scale=1.2, size=(300, 3)), -6.65, 6.65)
    actions[7, 1] = 6.65
    rows = np.concatenate([rng.normal(size=(300, 11)), actions], axis=1).astype(np.float32)
    conf = rng.uniform(size=(300, 1))
    demos = load_demonstrations(write_released(tmp_path, rows, conf, "Hopper-v2"))
    assert demos.observations.shape == (300, 11) and demos.actions.shape == (300, 3)
    outside = np.mean(np.abs(demos.actions) > 1)
    assert 0.3 < outside < 0.5 and np.abs(demos.actions).max() == np.float32(6.65)
    demos.check_env(stand_in_env("Hopper", 11, 3))


def test_actions_beyond_the_bound_multiple_are_refused():
    env = stand_in_env("Hopper", 11, 3, bound=0.4)  # ACTION_BOUND_MULTIPLE x 0.4 = 4
    actions = np.zeros((5, 3), np.float32)
    actions[2, 1] = -0.99 * ACTION_BOUND_MULTIPLE * 0.4
    Demonstrations(np.zeros((5, 11), np.float32), actions).check_env(env)
    actions[3, 2], actions[4, 0] = 4.2, -4.5
    message = (
        r"actions reach -4.5 \(row 4, dimension 0\), more than 10 x the action bound 0.4 of "
        r"Hopper: wrong --action-scale, or actions stored in other units\?"
    )
    with pytest.raises(DemonstrationError, match=message):
        Demonstrations(np.zeros((5, 11), np.float32), actions).check_env(env)


def test_an_authors_file_gets_its_known_action_scale_unless_one_is_given(tmp_path, capsys):
    """The authors' Pendulum file stores torque / 2: loaded by name it is multiplied by 2 (the
    sweep and classify say so and record it); a given scale, even 1, wins; other files get 1."""
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.demos import action_scale_note
    from pngail_jax.jobs import demonstrations as demos_job

    mixture = write_released(tmp_path, GOOD_ROWS)
    known = load_demonstrations(mixture)
    np.testing.assert_array_equal(known.actions, 2 * GOOD_ROWS[:, 3:])
    assert known.metadata["action_scale"] == 2.0
    assert known.metadata["action_scale_source"] == "known"
    assert "multiplied by 2 (--action-scale overrides)" in action_scale_note(known)
    given = load_demonstrations(mixture, action_scale=1.0)
    np.testing.assert_array_equal(given.actions, GOOD_ROWS[:, 3:])
    assert given.metadata["action_scale_source"] == "given" and action_scale_note(given) is None
    other = tmp_path / "other"
    other.mkdir()
    hopper = write_released(other, np.zeros((2, 14), np.float32), env_name="Hopper-v2")
    assert load_demonstrations(hopper).metadata["action_scale"] == 1.0
    assert action_scale_note(load_demonstrations(hopper)) is None
    with pytest.raises(DemonstrationError, match="npz set is stored in the environment's units"):
        (tmp_path / "set.npz").write_bytes(GOOD_NPZ)
        load_demonstrations(tmp_path / "set.npz", action_scale=2.0)
    # The sweep's loader: the config's None is the known scale, 1.0 is the stored units.
    demos, _ = demos_job.load_or_make_demos(RunConfig(demos=str(mixture)))
    np.testing.assert_array_equal(demos.actions, known.actions)
    demos, _ = demos_job.load_or_make_demos(RunConfig(demos=str(mixture), action_scale=1.0))
    np.testing.assert_array_equal(demos.actions, GOOD_ROWS[:, 3:])


def test_a_plain_file_of_rows_loads_for_any_environment_by_its_sizes(tmp_path):
    """Any .npy of rows [s, a] (not an authors' file): split by the environment's sizes, with a
    confidence file or none; without sizes the error says how to give them."""
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.jobs import demonstrations as demos_job

    rows = np.random.default_rng(0).uniform(-1, 1, (6, 4)).astype(np.float32)
    path, conf = tmp_path / "mine.npy", tmp_path / "scores.npy"
    np.save(path, rows)
    np.save(conf, np.linspace(0, 1, 6))
    with pytest.raises(DemonstrationError, match=r"not an authors' file; give the environment"):
        load_demonstrations(path)
    env = envs.make("Pendulum-v1")
    demos, _ = demos_job.load_or_make_demos(RunConfig(demos=str(path), conf=str(conf)), env=env)
    np.testing.assert_array_equal(demos.observations, rows[:, :3])
    np.testing.assert_array_equal(demos.actions, rows[:, 3:])  # no scale for a plain file
    np.testing.assert_allclose(demos.confidence, np.linspace(0, 1, 6))
    assert "env" not in demos.metadata and demos.metadata["action_scale"] == 1.0
    assert load_demonstrations(path, observation_size=3).confidence is None
    with pytest.raises(DemonstrationError, match=r"rows have 4 columns, but the environment's"):
        load_demonstrations(path, observation_size=3, action_size=2)
    # A config names its confidence file, so a resume checks it too.
    inputs = demos_job.input_files(RunConfig(demos=str(path), conf=str(conf)), str(path))
    assert set(inputs) == {"demonstrations", "confidence file"}


def test_return_range_from_flags_or_a_measured_random_policy():
    """--optimal-return alone: the random end is measured (uniform random actions, a fixed
    key: the same number twice); both flags: taken as given; neither: the file's own."""
    from pngail_jax.config.run_config import RunConfig
    from pngail_jax.jobs import demonstrations as demos_job

    env = envs.make("Pendulum-v1")
    plain = Demonstrations(np.zeros((4, 3), np.float32), np.zeros((4, 1), np.float32))
    assert demos_job.resolve_return_range(RunConfig(), plain, env) == (None, "none")
    given = RunConfig(random_return=-1200, optimal_return=-150)
    assert demos_job.resolve_return_range(given, plain, env)[0] == [-1200.0, -150.0]
    measured, source = demos_job.resolve_return_range(RunConfig(optimal_return=-150), plain, env)
    assert -1500 < measured[0] < -900 and measured[1] == -150.0  # Pendulum's random policy
    assert "measured" in source
    assert demos_job.resolve_return_range(RunConfig(optimal_return=-150), plain, env)[0] == measured
    with pytest.raises(demos_job.RunError, match=r"--optimal-return -2000 is not above the random"):
        demos_job.resolve_return_range(RunConfig(optimal_return=-2000), plain, env)
    with pytest.raises(ValueError, match="random_return needs optimal_return"):
        RunConfig(random_return=-1200)
    with pytest.raises(ValueError, match=r"optimal_return \(-1300.0\) must be above"):
        RunConfig(random_return=-1200, optimal_return=-1300)


@needs_authors_pendulum
def test_the_authors_pendulum_file_times_1000_is_refused(tmp_path):
    rows = np.load(AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy")
    conf = np.load(AUTHORS_PENDULUM / "Pendulum-v1_mixture_conf.npy")
    demos = load_released(write_released(tmp_path, rows * 1000, conf), action_scale=2.0)
    with pytest.raises(DemonstrationError, match=r"more than 10 x the action bound 2 of Pend"):
        demos.check_env(envs.make("Pendulum-v1"))


# --- property-based: any bytes, any arrays -------------------------------------------------

MAGIC_1_0 = b"\x93NUMPY\x01\x00"
HEADER_DTYPES = ["<f4", ">f8", "<f2", "|O", "<U3", "<c8", "|V8", "<M8[s]", "|b1", "<i8", "x"]


@st.composite
def npy_headers(draw):
    """A .npy file whose header names any dtype and shape, followed by any bytes."""
    descr = draw(st.sampled_from(HEADER_DTYPES))
    shape = tuple(draw(st.lists(st.integers(-2, 10**12), max_size=3)))
    header = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n".encode()
    return MAGIC_1_0 + len(header).to_bytes(2, "little") + header + draw(st.binary(max_size=80))


def edits_of(good: bytes):
    """Truncations and one-byte changes of ``good``."""
    return st.one_of(
        st.integers(0, len(good)).map(lambda n: good[:n]),
        st.tuples(st.integers(0, len(good) - 1), st.integers(0, 255)).map(
            lambda edit: good[: edit[0]] + bytes([edit[1]]) + good[edit[0] + 1 :]
        ),
    )


ANY_NPY_BYTES = st.one_of(
    st.binary(max_size=200),
    st.binary(max_size=120).map(lambda tail: MAGIC_1_0 + tail),
    npy_headers(),
    edits_of(GOOD_NPY),
)


def assert_loads_or_names(load, *names: Path):
    """``load()`` returns valid demonstrations or raises a one-line ``DemonstrationError``
    naming one of ``names``; any other exception fails the test."""
    try:
        demos = load()
    except DemonstrationError as error:
        assert any(str(name) in str(error) for name in names), str(error)
        assert "\n" not in str(error), str(error)
        event(" ".join(str(error).split(": ")[1].split()[:4]))  # --hypothesis-show-statistics
        return None
    event("loaded")
    assert isinstance(demos, Demonstrations) and demos.num_rows > 0
    assert np.isfinite(demos.inputs).all()
    return demos


@no_runtime_warnings
@HYPOTHESIS
@given(content=ANY_NPY_BYTES, as_confidence=st.booleans())
def test_any_bytes_as_a_released_file_load_or_raise_naming_it(tmp_path, content, as_confidence):
    if as_confidence:
        mixture = write_released(tmp_path, GOOD_ROWS, content)
    else:
        mixture = write_released(tmp_path, content)
    bad = mixture.with_name("Pendulum-v1_mixture_conf.npy") if as_confidence else mixture
    assert_loads_or_names(lambda: load_released(mixture), bad)


@no_runtime_warnings
@HYPOTHESIS
@given(content=st.one_of(st.binary(max_size=300), edits_of(GOOD_NPZ)))
def test_any_bytes_as_an_npz_file_load_or_raise_naming_it(tmp_path, content):
    path = tmp_path / "demos.npz"
    path.write_bytes(content)
    assert_loads_or_names(lambda: load_demonstrations(path), path)


# Any shape (0-3 dims) and any values, NaN and infinities included.
FLOAT_ARRAYS = hnp.arrays(
    dtype=hnp.floating_dtypes(sizes=(16, 32, 64)),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5),
)


def matrices(num_rows: int, num_columns: int, low=-3.0, high=3.0):
    """float32[num_rows, num_columns] in [low, high], or, a fifth of the time, any array."""
    values = st.floats(low, high, width=32)
    good = hnp.arrays(np.float32, (num_rows, num_columns), elements=values)
    return st.one_of(good, good, good, good, FLOAT_ARRAYS)


@no_runtime_warnings
@HYPOTHESIS
@given(data=st.data(), num_rows=st.integers(1, 4))
def test_any_float_arrays_as_released_files_load_or_raise_naming_a_file(tmp_path, data, num_rows):
    rows = data.draw(matrices(num_rows, 4), "rows")
    conf = data.draw(matrices(num_rows, 1, 0.0, 1.0), "conf")
    mixture = write_released(tmp_path, rows, conf)
    conf_path = mixture.with_name("Pendulum-v1_mixture_conf.npy")
    demos = assert_loads_or_names(lambda: load_released(mixture), mixture, conf_path)
    if demos is not None:
        assert demos.observations.shape == (len(rows), 3) and demos.confidence.shape == (len(rows),)


@st.composite
def npz_fields(draw):
    """The arrays of a demonstrations .npz: mostly well formed, any of them possibly not."""
    num_rows = draw(st.integers(1, 4))
    any_mask = hnp.arrays(np.bool_, hnp.array_shapes(min_dims=0, max_dims=2, max_side=5))
    any_ids = hnp.arrays(np.int32, hnp.array_shapes(min_dims=0, max_dims=2, max_side=5))
    candidates = {
        "observations": matrices(num_rows, 3),
        "actions": matrices(num_rows, 1),
        "confidence": matrices(num_rows, 1, 0.0, 1.0).map(lambda c: c.reshape(-1)),
        "labelled": st.one_of(hnp.arrays(np.bool_, num_rows), any_mask),
        "trajectory_ids": st.one_of(hnp.arrays(np.int32, num_rows), any_ids),
    }
    present = draw(st.sets(st.sampled_from(list(candidates))))
    present |= draw(st.sampled_from([{"observations", "actions"}] * 3 + [set()]))
    return {name: draw(candidates[name], name) for name in sorted(present)}


RETURNS = st.one_of(st.none(), st.just((-100.0, 250.0)), st.tuples(st.floats(), st.floats()))


@no_runtime_warnings
@pytest.mark.filterwarnings("ignore:.*normalised returns run backwards:UserWarning")
@HYPOTHESIS
@given(fields=npz_fields(), returns=RETURNS)
def test_any_arrays_in_an_npz_load_or_raise_naming_it(tmp_path, fields, returns):
    path = tmp_path / "demos.npz"
    metadata = {}
    if returns is not None:
        metadata = {"random_return": returns[0], "optimal_return": returns[1]}
    np.savez(
        path,
        **fields,
        metadata_json=np.asarray(json.dumps(metadata)),
        format_version=np.asarray(1),
    )
    demos = assert_loads_or_names(lambda: load_npz(path), path)
    if demos is not None:
        assert demos.metadata == metadata


# --- the labelled mask ---------------------------------------------------------------------


@jax.jit
def _splits(keys, confidence, ratios, allowed=None):
    """Splits of 9 rows with noise, one per key and ratio; ``allowed`` None: no mask."""
    return jax.vmap(lambda key, ratio: make_split(key, confidence, 9, ratio, 0.1, allowed))(
        keys, ratios
    )


@HYPOTHESIS
@given(
    allowed=hnp.arrays(np.bool_, 12),
    seed=st.integers(0, 2**31 - 1),
    ratios=hnp.arrays(np.float32, 4, elements=st.floats(0.0625, 0.9375, width=32)),
)
def test_split_labels_only_allowed_rows_under_vmap(allowed, seed, ratios):
    confidence = jnp.linspace(0.0, 1.0, 12)
    keys = jax.random.split(jax.random.key(seed), 4)
    split = jax.device_get(_splits(keys, confidence, ratios, allowed))
    plain = jax.device_get(_splits(keys, confidence, ratios, np.ones(12, bool)))
    for row in range(4):
        drawn_allowed = allowed[split.indices[row]]
        assert allowed[split.indices[row][split.labelled[row]]].all()
        requested = int(np.round(ratios[row] * np.float32(9)))  # float32, as make_split
        expected = min(requested, int(drawn_allowed.sum()))
        assert split.labelled[row].sum() == expected
        # The same rows are drawn as without a mask; allowed ones first, in drawn order.
        assert sorted(split.indices[row]) == sorted(plain.indices[row])
        np.testing.assert_array_equal(
            split.indices[row][drawn_allowed], [i for i in plain.indices[row] if allowed[i]]
        )


def test_an_all_true_mask_is_no_mask_bit_for_bit():
    confidence = jnp.linspace(0.0, 1.0, 12)
    keys = jax.random.split(jax.random.key(3), 4)
    ratios = jnp.array([0.1, 0.3, 0.5, 0.9])
    unmasked = _splits(keys, confidence, ratios)
    masked = _splits(keys, confidence, ratios, np.ones(12, bool))
    for got, expected in zip(jax.tree.leaves(masked), jax.tree.leaves(unmasked), strict=True):
        np.testing.assert_array_equal(got, expected)


def _masked_npz(path: Path, num_allowed: int) -> Path:
    """40 rows; rows outside the mask have confidence 0.125 exactly, the rest 0.5 to 1."""
    rng = np.random.default_rng(0)
    allowed = np.zeros(40, bool)
    allowed[rng.permutation(40)[:num_allowed]] = True
    confidence = np.where(allowed, rng.uniform(0.5, 1.0, 40), 0.125).astype(np.float32)
    demos = Demonstrations(
        observations=rng.normal(size=(40, 3)).astype(np.float32),
        actions=rng.uniform(-1, 1, size=(40, 1)).astype(np.float32),
        confidence=confidence,
        labelled=allowed,
    )
    save_npz(path, demos)
    return path


def test_classify_labels_only_the_rows_the_file_allows(tmp_path, monkeypatch):
    from pngail_jax import confidence as confidence_module
    from pngail_jax.programs import classify

    def count_labelled(predicted, true_confidence, labelled):
        """In place of MAE / RMSE: labelled rows outside the mask, and labelled rows."""
        outside = jnp.sum(labelled & (true_confidence == 0.125))
        return {"mae": outside.astype(jnp.float32), "rmse": labelled.sum().astype(jnp.float32)}

    def untrained(config, spec, inputs, confidence, labelled, key):
        """In place of the classifier (whose compilation takes seconds): predicts 0.5."""
        metrics = {"bsc/clip_active": jnp.zeros(config.num_steps)}
        return jnp.where(labelled, confidence, 0.5), inputs[:, 0], metrics

    monkeypatch.setattr(confidence_module, "confidence_errors", count_labelled)
    monkeypatch.setattr(confidence_module, "train_classifier", untrained)
    monkeypatch.setattr(confidence_module, "risk_estimator_variance", lambda *_: jnp.zeros(()))
    path = _masked_npz(tmp_path / "masked.npz", num_allowed=20)
    argv = ["--demos", str(path), "--label-ratio", "0.25", "--classifier-steps", "20"]
    summary = classify.main([*argv, "--seeds", "3", "--classifiers", "bsc"])
    assert summary["bsc"]["mae_mean"] == 0.0  # the 20 rows outside are never labelled
    assert summary["bsc"]["rmse_mean"] == 10.0  # round(0.25 * 40), all from the 20 allowed


def test_classify_refuses_a_mask_that_allows_too_few_rows(tmp_path):
    from pngail_jax.programs import classify

    path = _masked_npz(tmp_path / "masked.npz", num_allowed=3)
    with pytest.raises(SystemExit) as exit_info:
        classify.main(["--demos", str(path), "--label-ratio", "0.25"])
    message = str(exit_info.value.code)
    assert message.startswith(f"classify: {path}: its labelled mask allows only 3 of 40 rows")
    assert "fewer than the 10 asked for (lower --label-ratio or --num-demos)" in message


def test_the_trainer_passes_the_mask_to_the_split_and_checks_ratios(tmp_path, monkeypatch):
    from pngail_jax.adversarial.methods import method_spec

    demos = load_npz(_masked_npz(tmp_path / "masked.npz", num_allowed=6))
    trainer = adversarial.AdversarialTrainer(
        adversarial.AdversarialConfig(), envs.make("Pendulum-v1"), demos
    )
    trainer.check_label_ratios([0.1, 0.15])  # round(0.15 * 40) = 6 rows: allowed
    with pytest.raises(DemonstrationError, match="label ratio 0.2 of 40 rows asks for 8 lab"):
        trainer.check_label_ratios([0.1, 0.2])
    seen = []

    def spy(*args):
        seen.append(np.asarray(args[5]))
        return make_split(*args)

    monkeypatch.setattr(adversarial, "make_split", spy)
    jax.eval_shape(
        trainer.init,
        adversarial.AdversarialHyperparams.create(),
        method_spec("pngail"),
        jax.random.key(0),
    )
    np.testing.assert_array_equal(seen[0], demos.labelled)


# --- classify's flags and load errors ---------------------------------------------------


def test_classify_speaks_the_sweeps_names_and_keeps_the_old_ones_with_a_note(capsys):
    from pngail_jax.programs import classify

    old = ["--steps", "7", "--eps", "0.05", "--traj-size", "9", "--methods", "bsc"]
    args = classify.parse_args(["--demos", "any.npy", *old])
    assert (args.classifier_steps, args.bsc_eps, args.num_demos) == (7, 0.05, 9)
    assert args.classifiers == ["bsc"]
    err = capsys.readouterr().err
    for old_flag, new_flag in classify.DEPRECATED_FLAGS.items():
        assert f"note: {old_flag} is deprecated; it is now {new_flag}" in err
    new = ["--classifier-steps", "7", "--bsc-eps", "0.05", "--num-demos", "9"]
    assert vars(classify.parse_args(["--demos", "any.npy", *new, "--classifiers", "bsc"])) == (
        vars(args)
    )
    assert "deprecated" not in capsys.readouterr().err


NUM_DEMOS = "--num-demos must be at least 2 (one labelled and one unlabelled row)"


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--noise", "nan"], "--noise must be a finite number >= 0, got nan"),
        (["--noise", "inf"], "--noise must be a finite number >= 0, got inf"),
        (["--noise", "-0.1"], "--noise must be a finite number >= 0, got -0.1"),
        (["--bsc-eps", "nan"], "--bsc-eps must be a finite number > 0, got nan"),
        (["--bsc-eps", "0"], "--bsc-eps must be a finite number > 0, got 0.0"),
        (["--label-ratio", "nan"], "--label-ratio must be in (0, 1), got nan"),
        (["--num-demos", "0"], f"{NUM_DEMOS}, got 0"),
        (["--num-demos", "-3"], f"{NUM_DEMOS}, got -3"),
        (["--action-scale", "0"], "--action-scale must be a finite number > 0, got 0.0"),
        (["--action-scale", "-2"], "--action-scale must be a finite number > 0, got -2.0"),
        (["--action-scale", "nan"], "--action-scale must be a finite number > 0, got nan"),
        (["--json", "."], "--json . is a directory; give the path of a file to write"),
        (  # finished work: replaced only with --overwrite
            ["--json", "pyproject.toml"],
            "--json pyproject.toml exists: choose another file, or pass --overwrite",
        ),
    ],
)
def test_classify_refuses_bad_flags_naming_them(capsys, flags, message):
    from pngail_jax.programs import classify

    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        classify.parse_args(["--demos", "any.npy", *flags])
    assert f"python -m experiments.classify: error: {message} (usage:" in capsys.readouterr().err
    if flags[1] == "pyproject.toml":
        assert classify.parse_args(["--demos", "any.npy", *flags, "--overwrite"]).overwrite


def test_classify_load_errors_are_one_line_naming_the_file(tmp_path):
    from pngail_jax.programs import classify

    mixture = write_released(tmp_path, bytes(range(7, 250, 3)))
    for demos, expected in [
        (mixture, f"mixture file {mixture}: is not a NumPy .npy file (bad header)"),
        (tmp_path / "missing.npz", f"demonstrations not found: {tmp_path}/missing.npz"),
    ]:
        with pytest.raises(SystemExit) as exit_info:
            classify.main(["--demos", str(demos)])
        assert exit_info.value.code == f"classify: {expected}"
    save_npz(tmp_path / "bare.npz", Demonstrations(GOOD_ROWS[:, :3], GOOD_ROWS[:, 3:]))
    with pytest.raises(SystemExit, match="bare.npz: these demonstrations carry no confidence"):
        classify.main(["--demos", str(tmp_path / "bare.npz")])
