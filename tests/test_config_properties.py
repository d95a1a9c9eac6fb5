"""Inputs you can trust: arbitrary values for every config field and flag give either a valid
result or an error naming the field or flag, never another exception (hypothesis).

No JAX compilation here: configs and parsers only. Then the command-line programs' explicit
cases: NaN and infinite numbers, non-positive counts and bad output directories fail while
the flags are parsed, before anything runs.
"""

import argparse
import contextlib
import dataclasses
import io
import json

import pytest
from hypothesis import given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

from pngail_jax import envs
from pngail_jax.adversarial.methods import METHOD_NAMES
from pngail_jax.analysis.tracking import BACKENDS as LOG_BACKENDS
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.learner import FISHER_FORMS, LearnerConfig, PPOConfig, TRPOConfig
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.settings import RunSettings
from pngail_jax.config.validation import ConfigError
from pngail_jax.programs import cli, compare_settings, sweep
from pngail_jax.rl.learners import LEARNERS

PROPERTY = hypothesis_settings(max_examples=50, deadline=None, database=None, derandomize=True)

# -- values ----------------------------------------------------------------------------------

# JSON's scalars, with the numbers JSON cannot hold but Python callers can pass (NaN, inf,
# ints beyond float's range). Texts hold no ":" (an env "module:factory" would import it).
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-3, max_value=400),
    st.integers(),
    st.just(10**400),
    st.floats(),
    st.text(max_size=6).filter(lambda text: ":" not in text),
)
JUNK = st.recursive(
    SCALARS,
    lambda children: (
        st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=4), children, max_size=2)
    ),
    max_leaves=6,
)
COUNTS = st.integers(min_value=-2, max_value=600) | JUNK
FLOATS = st.floats() | st.integers(min_value=-2, max_value=2) | st.floats(0, 1) | JUNK
PATHS = st.sampled_from(["/x/demos.npz", "/x/a_mixture.npy", "minari:pen", ""]) | JUNK


def tuples_of(items):
    return st.lists(items, max_size=4) | st.lists(items, max_size=3).map(tuple) | JUNK


FIELD_VALUES = {
    "env": st.sampled_from(["Pendulum-v1", "Hopper", "Walker2d", "CartPole", ""]) | SCALARS,
    "methods": tuples_of(st.sampled_from(METHOD_NAMES) | SCALARS)
    | st.lists(st.sampled_from(METHOD_NAMES), min_size=1, max_size=3, unique=True),
    "seeds": COUNTS,
    "iterations": COUNTS | st.integers(1, 60).map(lambda n: 10 * n),
    "label_ratios": tuples_of(FLOATS),
    "noise_stds": tuples_of(FLOATS),
    "seed": COUNTS | st.integers(min_value=2**63 - 2, max_value=2**63 + 2),
    "demos": PATHS,
    "conf": PATHS,
    "confidence_field": PATHS,
    "action_scale": FLOATS | st.none(),
    "random_return": FLOATS | st.none(),
    "optimal_return": FLOATS | st.none(),
    "num_demos": COUNTS,
    "chunk_iterations": COUNTS,
    "settings": st.builds(
        RunSettings,
        num_envs=st.integers(1, 50),
        eval_every=st.sampled_from([1, 7, 10, 50]),
        solver_iterations=st.none() | st.integers(1, 4),
    )
    | JUNK,
    "classifier": st.builds(
        ClassifierConfig,
        num_steps=st.integers(1, 100),
        learning_rate=st.floats(1e-6, 1) | FLOATS,
        hidden_sizes=st.lists(st.integers(1, 64), max_size=2) | tuples_of(COUNTS),
        dropout_rate=st.floats(0, 0.9) | FLOATS,
    )
    | JUNK,
    "bsc_eps": FLOATS,
    "learner": st.sampled_from(LEARNERS)
    | st.builds(
        LearnerConfig,
        name=st.sampled_from(LEARNERS),
        trpo=st.builds(TRPOConfig, fisher=st.sampled_from(FISHER_FORMS)),
        ppo=st.builds(PPOConfig, num_epochs=st.integers(1, 5), normalize_rewards=st.booleans()),
    )
    | JUNK
    | st.dictionaries(
        st.sampled_from(["name", "trpo", "ppo", "x"]),
        JUNK | st.sampled_from(LEARNERS) | st.fixed_dictionaries({"fisher": JUNK}),
        max_size=2,
    ),
    "discriminator_hidden_sizes": tuples_of(COUNTS),
    "cpu_devices": COUNTS,
    "log": tuples_of(st.sampled_from(LOG_BACKENDS) | SCALARS),
    "phase_sizes": st.sampled_from(["codebase", "check", "paper"]) | SCALARS,
    "preset_name": PATHS,
    "baseline": st.sampled_from([*METHOD_NAMES, "trex"]) | SCALARS,
    "grid_axes": st.lists(
        st.tuples(
            st.sampled_from(["max_kl", "gamma", "pn_coef", "num_envs", "label_ratio", "x"])
            | SCALARS,
            st.lists(FLOATS | SCALARS, max_size=3),
        ),
        max_size=2,
    )
    | JUNK,
}
# The fields a field's error may name besides its own: settings' evaluation interval must
# divide the iterations ("iterations (300) must be a multiple of the evaluation interval").
ALSO_NAMED = {"settings": ("iterations",)}
# What a message about a key of a saved file may call it besides its name.
ALSO_CALLED = {
    "methods": ("method",),
    "label_ratios": ("label ratios",),
    "noise_stds": ("noise stds",),
    "classifier": ("ClassifierConfig.",),
    "grid_axes": ("grid axis",),
}


def test_every_field_has_values_to_try():
    assert set(FIELD_VALUES) == {field.name for field in dataclasses.fields(RunConfig)}


def assert_names(error: ConfigError, name: str) -> None:
    """The error names ``name`` (or a field inside it) as its field: the sweep calls that
    field by its flag."""
    assert error.field.split(".")[0] in (name, *ALSO_NAMED.get(name, ())), (name, str(error))


def assert_says(error: Exception, *names: str) -> None:
    message = str(error)
    assert any(name in message for name in names), (names, message)


def assert_stored_types(config: RunConfig) -> None:
    """A valid config holds exactly its annotated types, so its JSON reads back equal."""

    def kinds(values, kind):
        return type(values) is tuple and all(type(value) is kind for value in values)

    assert type(config.env) is str and kinds(config.methods, str) and kinds(config.log, str)
    assert kinds(config.label_ratios, float) and kinds(config.noise_stds, float)
    assert kinds(config.discriminator_hidden_sizes, int)
    for name in ("seeds", "iterations", "seed", "chunk_iterations"):
        assert type(getattr(config, name)) is int, name
    for name in ("num_demos", "cpu_devices"):
        assert getattr(config, name) is None or type(getattr(config, name)) is int, name
    for name in ("demos", "conf", "confidence_field", "preset_name"):
        assert getattr(config, name) is None or type(getattr(config, name)) is str, name
    assert type(config.learner) is LearnerConfig and type(config.learner.name) is str
    for name in ("action_scale", "bsc_eps", "random_return", "optimal_return"):
        assert getattr(config, name) is None or type(getattr(config, name)) is float, name
    assert type(config.settings) is RunSettings and type(config.classifier) is ClassifierConfig
    classifier = config.classifier
    assert kinds(classifier.hidden_sizes, int) and type(classifier.learning_rate) is float


def assert_round_trips(config: RunConfig) -> None:
    assert_stored_types(config)
    assert RunConfig.from_dict(config.to_dict()) == config
    document = json.dumps(config.to_dict(), allow_nan=False)  # strict JSON: nothing non-finite
    assert RunConfig.from_dict(json.loads(document)) == config


# -- RunConfig -------------------------------------------------------------------------------


@PROPERTY
@given(data=st.data())
def test_any_field_value_gives_a_valid_config_or_an_error_naming_the_field(data):
    name = data.draw(st.sampled_from(sorted(FIELD_VALUES)), label="field")
    value = data.draw(FIELD_VALUES[name], label="value")
    try:
        config = RunConfig(**{name: value})
    except ConfigError as error:  # only ConfigError: the sweep names the field's flag
        assert_names(error, name)
        return
    assert_round_trips(config)


SETTINGS_KEYS = [field.name for field in dataclasses.fields(RunSettings)]
CLASSIFIER_KEYS = [field.name for field in dataclasses.fields(ClassifierConfig)]


@PROPERTY
@given(data=st.data())
def test_a_json_file_with_any_value_anywhere_loads_right_or_names_the_key(data):
    """One key of a saved config.json (a field, a settings or classifier key, or a stray
    key) set to any JSON value."""
    document = json.loads(json.dumps(RunConfig().to_dict()))
    where = data.draw(st.sampled_from(["field", "settings", "classifier", "stray"]))
    value = data.draw(JUNK.filter(lambda v: v != 10**400), label="value")  # beyond JSON
    if where == "field":
        key = data.draw(st.sampled_from(sorted(FIELD_VALUES)), label="key")
        document[key] = value
        names = (key, *ALSO_CALLED.get(key, ()))
    elif where == "stray":
        key = data.draw(st.text(min_size=1, max_size=5).filter(lambda k: k not in document))
        document[key] = value
        names = (repr(key),)
    else:
        known = SETTINGS_KEYS if where == "settings" else CLASSIFIER_KEYS
        key = data.draw(st.sampled_from(known) | st.text(max_size=5), label="key")
        document[where][key] = value
        names = (key, repr(key), "settings.eval_every")
    document = json.loads(json.dumps(document))  # what a file holds: lists, NaN allowed
    try:
        config = RunConfig.from_dict(document)
    except ValueError as error:
        assert_says(error, *names)
        return
    assert_round_trips(config)


@PROPERTY
@given(
    name=st.sampled_from(SETTINGS_KEYS),
    value=COUNTS | st.booleans() | st.sampled_from([*envs.PHYSICS, "mjx2"]),
)
def test_any_settings_value_is_valid_or_named(name, value):
    try:
        settings = RunSettings(**{name: value})
    except ConfigError as error:
        assert error.field == name and str(error).startswith(f"RunSettings.{name} ")
        return
    stored = getattr(settings, name)
    assert stored == value
    if name in ("normalize_observations", "stagger_starts"):
        assert type(stored) is bool
    elif name == "physics":  # an engine's name, or None: the platform's
        assert stored is None or stored in envs.PHYSICS
    else:  # a count; the solver caps may be None (the task's own)
        solver_cap = name in ("solver_iterations", "ls_iterations")
        assert (type(stored) is int and stored >= 1) or (stored is None and solver_cap)


# -- command-line helpers: a value, or an exit naming the flag -------------------------------


def parse(parser: argparse.ArgumentParser, argv: list[str], then=lambda args: args):
    """(result, stderr) of parsing ``argv`` and calling ``then``; result None on an exit."""
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr):
        try:
            return then(parser.parse_args(argv)), stderr.getvalue()
        except SystemExit as exit_:
            assert exit_.code == 2
            return None, stderr.getvalue()


NUMBER_ITEMS = st.one_of(
    st.floats().map(repr),
    st.integers().map(str),
    st.sampled_from(["", " ", "nan", "-inf", "Infinity", "1e999", "0x10", "1_0", "--1", "x"]),
)
# "--": argparse hands the value "--" over as [] (it drops "--" from values).
NUMBER_TEXTS = (
    st.text(max_size=12) | st.just("--") | st.lists(NUMBER_ITEMS, max_size=4).map(",".join)
)


@PROPERTY
@given(text=NUMBER_TEXTS)
def test_comma_floats_gives_finite_numbers_or_names_the_flag(text):
    parser = argparse.ArgumentParser()
    parser.add_argument("--noise")
    values, stderr = parse(
        parser, [f"--noise={text}"], lambda args: cli.comma_floats(parser, "--noise", args.noise)
    )
    if values is None:
        assert "--noise" in stderr
    else:
        assert values and all(type(v) is float and abs(v) < float("inf") for v in values)
        assert len(values) == len(text.split(","))


NAME_TEXTS = st.text(max_size=12) | st.lists(
    st.sampled_from([*METHOD_NAMES, "", " gail ", "pu-gail"]), max_size=4
).map(",".join)


@PROPERTY
@given(text=NAME_TEXTS)
def test_known_names_gives_known_names_once_each_or_names_the_flag(text):
    parser = argparse.ArgumentParser()
    parser.add_argument("--methods")
    names, stderr = parse(
        parser,
        [f"--methods={text}"],
        lambda args: cli.known_names(parser, args.methods, METHOD_NAMES, "method", "--methods"),
    )
    if names is None:
        assert "--methods" in stderr
    else:
        assert names and set(names) <= set(METHOD_NAMES) and len(set(names)) == len(names)


@PROPERTY
@given(text=st.text(max_size=8) | st.integers().map(str) | st.floats().map(repr) | st.just("--"))
def test_check_positive_and_check_finite_give_a_valid_number_or_name_the_flag(text):
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int)
    parser.add_argument("--scale", type=float)

    def check(args):
        cli.check_positive(parser, args, ("seeds",))
        cli.check_finite(parser, args, ("scale",))
        return args

    for flag in ("--seeds", "--scale"):
        args, stderr = parse(parser, [f"{flag}={text}"], check)
        if args is None:
            assert flag in stderr
        elif flag == "--seeds":
            assert type(args.seeds) is int and args.seeds >= 1
        else:
            assert abs(args.scale) < float("inf")
    assert parse(parser, [], check)[0] is not None  # a flag not given is not checked


# -- the programs: bad values fail while parsing, naming the flag ----------------------------


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--noise", "inf"], "--noise values must be finite numbers, got 'inf'"),
        (["--noise", "nan"], "--noise values must be finite numbers, got 'nan'"),
        (["--noise", "0,,0.1"], "--noise: empty item in '0,,0.1'"),
        (
            ["--label-ratio", "0.2,1e999"],
            "--label-ratio values must be finite numbers, got '1e999'",
        ),
        (["--cpu-devices", "0"], "--cpu-devices must be a positive integer, got 0"),
        (["--cpu-devices", "-1"], "--cpu-devices must be a positive integer, got -1"),
        (["--action-scale", "inf"], "--action-scale must be finite and positive, got inf"),
        (["--bsc-eps", "nan"], "--bsc-eps must lie in (0, 0.5), got nan"),
        (
            ["--env", ".relative:make"],  # the import's own words (a relative module path)
            "--env: the 'package' argument is required to perform a relative import for "
            "'.relative'",
        ),
        # The sweep names the flag of a ConfigError's field (programs/flags.py), and the
        # comma lists' own errors name theirs.
        (["--seed", "-1"], "--seed must be an integer in [0, 2**63), got -1"),
        (["--methods", "gail,gail"], "--methods: method(s) ['gail'] given more than once"),
        (["--methods", "gail,"], "--methods: empty item in 'gail,'"),
    ],
)
def test_sweep_flags_are_refused_while_parsing(argv, message, capsys):
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(argv)
    assert f"python -m experiments.sweep: error: {message}" in capsys.readouterr().err


def test_sweep_conf_without_demos_names_the_flags(tmp_path, capsys):
    conf = tmp_path / "conf.npy"
    conf.write_bytes(b"")
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(["--conf", str(conf)])  # a ConfigError of field "conf"
    assert "error: --conf: a confidence file needs demos (made demonstrations carry their own)" in (
        capsys.readouterr().err
    )


def test_compare_settings_refuses_a_file_and_finished_work(tmp_path, capsys):
    file = tmp_path / "file"
    file.write_text("")
    flags = ["--env", "Hopper", "--out"]
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        compare_settings.parse_args([*flags, str(file)])
    assert f"--out {file} is a file, not a directory" in capsys.readouterr().err
    (tmp_path / "comparison.json").write_text("{}")
    with pytest.raises(SystemExit, match="^2$"):
        compare_settings.parse_args([*flags, str(tmp_path)])
    assert (
        f"--out {tmp_path} already holds a run of experiments.compare_settings: pass --overwrite"
    ) in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):  # the test's own file: not the program's
        compare_settings.parse_args([*flags, str(tmp_path), "--overwrite"])
    assert (
        f"--out {tmp_path} holds a run of experiments.compare_settings and files it did not "
        "make (file)"
    ) in capsys.readouterr().err
    file.unlink()
    assert compare_settings.parse_args([*flags, str(tmp_path), "--overwrite"]).overwrite
    with pytest.raises(SystemExit, match="^2$"):
        compare_settings.parse_args([*flags, str(tmp_path / "new"), "--arms", "table,table"])
    assert "--arms: arm(s) ['table'] given more than once" in capsys.readouterr().err


def test_one_name_and_one_default_per_concept_across_programs(tmp_path, capsys):
    """The same concept has the same flag and default in every program; the old spellings
    still parse, with a note; usage and errors say how to run the program."""
    from pngail_jax.programs import train_rl
    from pngail_jax.rl import TRPOConfig

    fisher = train_rl.parse_args([]).learner.trpo.fisher
    assert fisher == RunConfig().learner.trpo.fisher == TRPOConfig().fisher == "gauss_newton"
    out = ["--env", "Hopper", "--out", str(tmp_path / "new")]
    old = compare_settings.parse_args([*out, "--eval-episodes", "7"])
    assert old.num_eval_episodes == 7
    assert "--eval-episodes is deprecated; it is now --num-eval-episodes" in (
        capsys.readouterr().err
    )
    assert compare_settings.parse_args([*out, "--num-eval-episodes", "7"]).num_eval_episodes == 7
    assert train_rl.parse_args(["--env", "Hopper", "--fast-solver"]).solver == "fast"
    assert "--fast-solver is deprecated; it is now --solver fast" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):  # parser.error's; its line on stderr
        sweep.parse_args(["--seeds", "0"])
    err = capsys.readouterr().err
    assert err.splitlines() == [  # one line, no usage block above it
        "python -m experiments.sweep: error: --seeds must be a positive integer, got 0 "
        "(usage: python -m experiments.sweep --help)"
    ]


def test_a_long_silent_step_shows_its_elapsed_time():
    import io
    import time

    from pngail_jax.analysis.tracking import ticking

    stream = io.StringIO()  # not a terminal: whole lines, every `every` seconds
    with ticking("compiling", every=0.05, stream=stream):
        deadline = time.monotonic() + 30  # a busy machine may delay the ticker's thread
        while len(stream.getvalue().splitlines()) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "compiling ..." and len(lines) >= 3
    assert all(line.startswith("compiling ... ") and line.endswith(" s") for line in lines[1:])


def test_a_long_step_that_counts_its_steps_shows_them_and_the_time_left():
    import io
    import re
    import time

    from pngail_jax.analysis.tracking import StepCounter, ticking

    stream, counter = io.StringIO(), StepCounter()
    with ticking("ILID", every=0.05, stream=stream, counter=counter, total=200):
        deadline = time.monotonic() + 30
        while "steps" not in stream.getvalue() and time.monotonic() < deadline:
            time.sleep(0.01)
            if len(stream.getvalue().splitlines()) >= 2:  # a line before any report
                counter(50)
                counter(20)  # another cell's later report of fewer steps: the most is kept
    counted = [line for line in stream.getvalue().splitlines() if "steps" in line]
    assert counted, stream.getvalue()
    assert re.fullmatch(r"ILID \.\.\. \d+ s \(50 of 200 steps, about \d+ s left\)", counted[0])
