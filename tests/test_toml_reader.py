"""The one TOML reader of model, co-simulation and sweep files
(lpvest.core._toml): each getter's accept and refuse paths with the exact
message, the field paths, unknown and missing keys."""

from __future__ import annotations

import math
import re

import pytest

from lpvest.core._errors import DimensionError, ModelFileError
from lpvest.core._toml import TomlReader, element_path, field_path, key_text


@pytest.fixture
def reader() -> TomlReader:
    return TomlReader("f.toml")


def refused(message: str):
    """``pytest.raises`` for exactly this one-line message."""
    return pytest.raises(ModelFileError, match=f"^{re.escape(message)}$")


# -- field paths ---------------------------------------------------------------------------------

def test_keys_are_bare_when_plain_and_quoted_and_shortened_otherwise():
    assert key_text("step_size") == "step_size" and key_text("A-1") == "A-1" and key_text("2src") == "2src"
    assert key_text("a b") == "'a b'" and key_text("") == "''" and key_text("a.b") == "'a.b'"
    assert key_text("k" * 5000) == "'" + "k" * 15 + "..." + "k" * 5 + "' (5,000 characters)"
    assert key_text(3) == "3"  # a key of a Python dict given instead of a file


def test_paths_join_keys_with_dots_and_count_elements_from_one():
    assert field_path("", "steps") == "steps"
    assert field_path("components.sched", "fmu") == "components.sched.fmu"
    assert field_path("seeds", "a b") == "seeds.'a b'"
    assert element_path("connections", 1) == "connections[2]"


# -- errors --------------------------------------------------------------------------------------

def test_an_error_is_origin_where_message_and_the_file_alone_without_a_where(reader):
    assert str(reader.error("models.m.A", "has no terms")) == "f.toml: models.m.A: has no terms"
    assert str(reader.error("", "expected a table, found a list")) == "f.toml: expected a table, found a list"
    assert isinstance(reader.error("x", "y"), ModelFileError)


def test_a_library_error_inside_at_becomes_the_files_error_at_that_field(reader):
    with refused("f.toml: models.m: Q has shape (3, 2)"), reader.at("models.m"):
        raise DimensionError("Q has shape (3, 2)")
    with refused("f.toml: a: b"), reader.at("models.m"):  # already the file's error: unchanged
        raise reader.error("a", "b")
    with pytest.raises(KeyError), reader.at("models.m"):  # not a deliberate error: not reworded
        raise KeyError("x")


# -- each getter: accepted, refused ------------------------------------------------------------------

def test_root_and_table(reader):
    top = reader.root({"a": {"b": 1}})
    assert top.where == "" and dict(top) == {"a": {"b": 1}}
    sub = top.table("a")
    assert sub.where == "a" and sub["b"] == 1 and len(sub) == 1 and list(sub) == ["b"]
    assert dict(top.table("c", required=False)) == {}
    with refused("f.toml: expected a table, found a list"):
        reader.root([1])
    with refused("f.toml: c: missing (expected a table)"):
        top.table("c")
    with refused("f.toml: a.b: expected a table, found a number (1)"):
        sub.table("b")
    with refused("f.toml: a.b: expected a table of start values, found a number (1)"):
        sub.table("b", what="a table of start values")


def test_string(reader):
    t = reader.root({"s": "x", "n": 3})
    assert t.string("s") == "x" and t.string("absent", "") == ""
    with refused("f.toml: n: expected a string, found a number (3)"):
        t.string("n")
    with refused("f.toml: absent: missing (expected a string)"):
        t.string("absent")
    with refused("f.toml: n: expected a folder (a path), found a number (3)"):
        t.string("n", what="a folder (a path)")


@pytest.mark.parametrize(("value", "number"), [(2, 2.0), (-0.5, -0.5), (0, 0.0), (2**63 - 1, 2.0**63)])
def test_number_accepts_integers_and_floats(reader, value, number):
    got = reader.root({"x": value}).number("x")
    assert got == number and type(got) is float


@pytest.mark.parametrize(("value", "message"), [
    (True, "expected a number, found a boolean (true)"),
    ("1", "expected a number, found a string ('1')"),
    ([1.0], "expected a number, found a list"),
    (math.nan, "expected a finite number, found a number (nan)"),
    (-math.inf, "expected a finite number, found a number (-inf)"),
    # a Python int of a dict given to sweep_spec: beyond the float range, and shortened in the message
    (10**400, "expected a finite number, found a number (1" + "0" * 36 + "...)"),
])
def test_number_refuses_what_is_not_a_finite_number(reader, value, message):
    with refused(f"f.toml: t.x: {message}"):
        reader.root({"t": {"x": value}}).table("t").number("x")


def test_positive_number(reader):
    t = reader.root({"h": 0.5, "zero": 0, "neg": -1.0, "s": "1"})
    assert t.number("h", positive=True) == 0.5 and t.number("absent", 1.0, positive=True) == 1.0
    with refused("f.toml: zero: expected a positive number, found a number (0)"):
        t.number("zero", positive=True)
    with refused("f.toml: neg: expected a positive number, found a number (-1.0)"):
        t.number("neg", positive=True)
    with refused("f.toml: s: expected a positive number, found a string ('1')"):
        t.number("s", positive=True)
    with refused("f.toml: absent: missing (expected a positive number)"):
        t.number("absent", positive=True)


@pytest.mark.parametrize(("minimum", "ok", "bad", "what"), [
    (None, -3, 2.0, "an integer"),
    (0, 0, -1, "a non-negative integer"),
    (1, 1, 0, "a positive integer"),
    (5, 5, 4, "an integer >= 5"),
])
def test_integer(reader, minimum, ok, bad, what):
    t = reader.root({"ok": ok, "bad": bad, "flag": True, "half": 2.5})
    assert t.integer("ok", minimum=minimum) == ok and t.integer("absent", 7, minimum=minimum) == 7
    with refused(f"f.toml: bad: expected {what}, found a number ({bad!r})"):
        t.integer("bad", minimum=minimum)
    with refused(f"f.toml: flag: expected {what}, found a boolean (true)"):
        t.integer("flag", minimum=minimum)
    with refused(f"f.toml: half: expected {what}, found a number (2.5)"):
        t.integer("half", minimum=minimum)


def test_boolean(reader):
    t = reader.root({"yes": True, "no": "no", "one": 1})
    assert t.boolean("yes") is True and t.boolean("absent", False) is False
    with refused("f.toml: no: expected true or false, found a string ('no')"):
        t.boolean("no")
    with refused("f.toml: one: expected true or false, found a number (1)"):
        t.boolean("one")
    with refused("f.toml: absent: missing (expected true or false)"):
        t.boolean("absent")


def test_choice_with_a_did_you_mean(reader):
    t = reader.root({"type": "affine", "typo": "afine", "far": "zzz", "n": 1})
    kinds = ["affine", "polytopic"]
    assert t.choice("type", kinds, noun="model type") == "affine"
    assert t.choice("absent", kinds, "polytopic", noun="model type") == "polytopic"
    with refused("f.toml: typo: unknown model type 'afine', did you mean 'affine'? "
                 "(expected one of: affine, polytopic)"):
        t.choice("typo", kinds, noun="model type")
    with refused("f.toml: far: unknown model type 'zzz' (expected one of: affine, polytopic)"):
        t.choice("far", kinds, noun="model type")
    with refused("f.toml: n: expected a string, found a number (1)"):
        t.choice("n", kinds, noun="model type")
    with refused("f.toml: absent: missing (expected one of: affine, polytopic)"):
        t.choice("absent", kinds, noun="model type")


def test_array_strings_and_numbers(reader):
    t = reader.root({"names": ["a", "b"], "mixed": ["a", 3], "one": "a", "empty": [], "nums": [1, 2.5],
                     "badnums": [1, True]})
    assert t.array("names") == ["a", "b"] and t.array("empty") == [] and t.array("absent", ()) == ()
    assert t.strings("names") == ["a", "b"] and t.numbers("nums") == [1.0, 2.5]
    with refused("f.toml: empty: expected a non-empty list, found a list"):
        t.array("empty", what="a non-empty list", nonempty=True)
    with refused("f.toml: one: expected a list of strings, found a string ('a')"):
        t.strings("one")
    with refused("f.toml: mixed[2]: expected a string, found a number (3)"):
        t.strings("mixed")
    with refused("f.toml: mixed[2]: expected 'component.variable', found a number (3)"):
        t.strings("mixed", what="'component.variable'")
    with refused("f.toml: one: expected a list of numbers, found a string ('a')"):
        t.numbers("one")
    with refused("f.toml: badnums[2]: expected a number, found a boolean (true)"):
        t.numbers("badnums")
    with refused("f.toml: absent: missing (expected a list of strings)"):
        t.strings("absent")


def test_value_gives_the_raw_value_of_a_required_key(reader):
    t = reader.root({"x": [1, {"a": 2}]})
    assert t.value("x", "anything") == [1, {"a": 2}]
    with refused("f.toml: y: missing (expected a matrix)"):
        t.value("y", "a matrix")


# -- keys ----------------------------------------------------------------------------------------

def test_unknown_keys_are_named_at_their_path_with_a_did_you_mean(reader):
    t = reader.root({"seeds": {"count": 3, "cout": 1}})
    seeds = t.table("seeds")
    seeds.check_keys({"count", "cout"})  # all known
    with refused("f.toml: seeds.cout: unknown key, did you mean 'count'? (expected one of: common, count, keys)"):
        seeds.check_keys({"count", "keys", "common"})
    with refused("f.toml: seeds.count: unknown key (expected one of: root)"):  # nothing close
        seeds.check_keys({"root"})
    with refused("f.toml: 'k k': unknown key (expected one of: a)"):
        reader.root({"k k": 1}).check_keys({"a"})


def test_the_first_unknown_key_in_sorted_order_is_named(reader):
    with refused("f.toml: b: unknown key (expected one of: z)"):
        reader.root({"c": 1, "b": 2}).check_keys({"z"})


def test_a_long_unknown_key_is_shortened(reader):
    with refused("f.toml: scheduling.'kkkkkkkkkkkkkkk...kkkkk' (5,000 characters): unknown key "
                 "(expected one of: lower, names, upper)"):
        reader.root({"scheduling": {"k" * 5000: 1}}).table("scheduling").check_keys({"names", "lower", "upper"})


def test_missing_required_keys_are_named_at_their_path_with_what_belongs_there(reader):
    t = reader.root({"models": {"m": {"A": [[1]]}}}).table("models").table("m")
    t.check_keys({"A", "C"}, {"A": "a matrix"})
    with refused("f.toml: models.m.C: missing (expected a matrix)"):
        t.check_keys({"A", "C"}, {"A": "a matrix", "C": "a matrix"})
    with refused("f.toml: models.m.F: unknown key (expected one of: C)"):  # unknown before missing
        reader.check_keys({"F": 1}, "models.m", {"C"}, {"C": "a matrix"})


# -- one style: the same mistake in a model, a co-simulation and a sweep file ----------------------

MODEL = """
[system]
name = "one"
title = "a model"

[scheduling]
names = ["p"]
lower = [-1.0]
upper = [1.0]

[models.m]
type = "affine"
A = { "1" = [[0.5]], p = [[0.1]] }
C = [[1.0]]
Q = [[0.1]]
R = [[0.01]]
"""

COSIM = """
title = "a co-simulation"
step_size = 1.0
steps = 10

[components.plant]
fmu = "plant.fmu"
"""

SWEEP = """
title = "a sweep"
cosim = "run.toml"

[metrics]
rms = { kind = "rms", of = "plant.y" }
"""


def _edit(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


#: mistake -> (the edit of each file: model, co-simulation, sweep) and the field each names
SAME_MISTAKES = {
    "a number where a string belongs": (
        [("title = \"a model\"", "title = 3"), ("title = \"a co-simulation\"", "title = 3"),
         ("title = \"a sweep\"", "title = 3")],
        ["system.title", "title", "title"],
        r"expected a string, found a number \(3\)",
    ),
    "a boolean where a number belongs": (
        [("C = [[1.0]]", "C = [[true]]"), ("step_size = 1.0", "step_size = true"),
         ('of = "plant.y" }', 'of = "plant.y", start = true }')],
        [r"models.m.C[1,1]", "step_size", "metrics.rms.start"],
        r"expected a (number or formula|positive number|non-negative integer), found a boolean \(true\)",
    ),
    "a misspelt key": (
        [('title = "a model"', 'titel = "a model"\ntitle = "a model"'),
         ('fmu = "plant.fmu"', 'fmu = "plant.fmu"\nfmuu = 1'),
         ('of = "plant.y" }', 'of = "plant.y", strat = 1 }')],
        ["system.titel", "components.plant.fmuu", "metrics.rms.strat"],
        r"unknown key, did you mean '(title|fmu|start)'\? \(expected one of: [\w, ]+\)",
    ),
    "a missing required key": (
        [("R = [[0.01]]\n", ""), ('fmu = "plant.fmu"\n', "parameters = {}\n"),
         ('kind = "rms", of = "plant.y"', 'kind = "rms"')],
        ["models.m.R", "components.plant.fmu", "metrics.rms.of"],
        r"missing \(expected (a matrix|a built FMU's name or a path to an \.fmu file|"
        r"a recorded variable 'component\.variable')\)",
    ),
}


@pytest.mark.parametrize("mistake", list(SAME_MISTAKES))
def test_the_same_mistake_reads_the_same_in_model_cosimulation_and_sweep_files(tmp_path, mistake):
    from lpvest.cosim._cosimfile import load_cosim
    from lpvest.sweep import load_sweep
    from lpvest.systems import load_system

    edits, fields, message = SAME_MISTAKES[mistake]
    (tmp_path / "plant.fmu").write_bytes(b"")  # the file is looked for, not opened, when a sweep file is read
    texts = {"model.toml": MODEL, "run.toml": COSIM, "sweep.toml": SWEEP}
    loaders = {"model.toml": load_system, "run.toml": load_cosim, "sweep.toml": load_sweep}
    for (name, text), (old, new), field in zip(texts.items(), edits, fields, strict=True):
        for other, good in texts.items():
            (tmp_path / other).write_text(good)
        path = tmp_path / name
        path.write_text(_edit(text, old, new))
        with pytest.raises(ModelFileError) as info:
            loaders[name](path)
        assert re.fullmatch(f"{re.escape(str(path))}: {re.escape(field)}: {message}", str(info.value)), \
            str(info.value)


def test_the_unedited_files_of_the_same_mistake_test_are_accepted(tmp_path):
    from lpvest.cosim._cosimfile import load_cosim
    from lpvest.sweep import load_sweep
    from lpvest.systems import load_system

    (tmp_path / "plant.fmu").write_bytes(b"")
    for name, text in {"model.toml": MODEL, "run.toml": COSIM, "sweep.toml": SWEEP}.items():
        (tmp_path / name).write_text(text)
    assert load_system(tmp_path / "model.toml").name == "one"
    assert load_cosim(tmp_path / "run.toml").n_steps == 10
    assert [m.name for m in load_sweep(tmp_path / "sweep.toml").metrics] == ["rms"]
