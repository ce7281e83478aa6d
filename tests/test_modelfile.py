"""Model files: round trip and every validation error path."""

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lpvest import (
    AffineLPV,
    InnovationLPV,
    LPVInputOutput,
    LTVInputOutput,
    LTVStateSpace,
    ModelFileError,
    PolytopicLPV,
    dump_system,
    example_systems,
    load_system,
    loads_system,
)
from lpvest.core._errors import shorten

EXAMPLES = [e.name for e in example_systems()]


def test_the_example_systems_are_there():
    assert EXAMPLES == ["cox-toth-ex1", "cox-toth-truncation", "peixoto-ex1", "peixoto-ex2", "sridhar-ltv"]


def _same_model(a, b, rng):
    assert type(a) is type(b)
    if isinstance(a, AffineLPV):
        for p in a.space.sample(rng, 5):
            for m1, m2 in zip(a.at(p), b.at(p), strict=True):
                np.testing.assert_array_equal(m1, m2)
        for n in ("Q", "S", "R"):
            np.testing.assert_array_equal(getattr(a.noise, n), getattr(b.noise, n))
        np.testing.assert_array_equal(a.x0, b.x0)
        np.testing.assert_array_equal(a.P0, b.P0)
    elif isinstance(a, PolytopicLPV):
        for m1, m2 in zip(a.vertices, b.vertices, strict=True):
            np.testing.assert_array_equal(m1, m2)
        if a.simplex_map is not None:
            pts = a.space.sample(rng, 5)
            np.testing.assert_array_equal(a.simplex_map.evaluate(pts), b.simplex_map.evaluate(pts))
        assert (a.affine is None) == (b.affine is None)
        if a.affine is not None:
            for k in a.affine.coefficients:
                np.testing.assert_array_equal(a.affine.coefficients[k], b.affine.coefficients[k])
    elif isinstance(a, InnovationLPV):
        back, ahead = a.window
        p = np.full((back + 6 + ahead, a.n_p), 0.5)
        e = rng.standard_normal((6, a.ny))
        np.testing.assert_array_equal(a.simulate(p, e=e).y, b.simulate(p, e=e).y)
    elif isinstance(a, LPVInputOutput):
        p = np.full((6, 1), 0.3)
        u, e = rng.standard_normal(6), rng.standard_normal(6)
        np.testing.assert_array_equal(a.simulate(p, u, e=e).y, b.simulate(p, u, e=e).y)
    elif isinstance(a, LTVInputOutput | LTVStateSpace):
        t = np.linspace(0, 2, 5)
        np.testing.assert_array_equal(a.simulate(t).x, b.simulate(t).x)
    else:  # pragma: no cover
        raise AssertionError(type(a))


@pytest.mark.parametrize("name", EXAMPLES)
def test_toml_round_trip(name, rng):
    first = load_system(name)
    text = dump_system(first)
    second = loads_system(text, origin="dumped")
    assert (second.name, second.title, second.default) == (first.name, first.title, first.default)
    assert list(second.models) == list(first.models)
    for key in first.models:
        _same_model(first.model(key), second.model(key), rng)
    # and the dump is a fixed point
    assert dump_system(second) == text


def test_a_models_arrays_are_read_only_copies():
    """A loaded model is shared: the instances of an FMU share its loaded model file
    (lpvest/fmi/_slave.py), so no user of a model may change what another sees. Every array
    field of every example model is read-only, and a model made from a caller's arrays holds
    copies: the caller's arrays stay theirs (writeable, unchanged)."""
    import dataclasses

    for e in example_systems():
        system = load_system(e.name)
        for key in system.models:
            model = system.model(key)
            for field in dataclasses.fields(model):
                value = getattr(model, field.name)
                if isinstance(value, np.ndarray):
                    assert not value.flags.writeable, (e.name, key, field.name)
                    with pytest.raises(ValueError, match="read-only"):
                        value[...] = 0.0
    from lpvest.core._scheduling import Monomial, SchedulingSpace

    space = SchedulingSpace(["p"], [0.0], [1.0])
    x0, P0, Cz = np.array([1.0]), np.array([[2.0]]), np.array([[1.0]])
    model = AffineLPV.from_matrices(space, [Monomial.component(0, space)], A={"1": [[0.5]], "p": [[0.2]]},
                                    C=[[1.0]], Q=[[0.1]], R=[[0.01]], x0=x0, P0=P0, Cz=Cz)
    assert all(not getattr(model, n).flags.writeable for n in ("x0", "P0", "Cz"))
    assert x0.flags.writeable and P0.flags.writeable and Cz.flags.writeable
    assert not np.shares_memory(model.x0, x0) and not np.shares_memory(model.P0, P0)
    inno = load_system("cox-toth-ex1").model("minimal")
    again = InnovationLPV(inno.dependence, inno.K, inno.innovation_covariance, x0=x0)
    assert not again.x0.flags.writeable and x0.flags.writeable and not np.shares_memory(again.x0, x0)
    ltv = LTVInputOutput(["1", "2"], ["1"], x0=x0.repeat(2))
    assert not ltv.x0.flags.writeable


def test_parameter_override():
    base = load_system("peixoto-ex2")
    assert base.parameters == {"rho": 1.0}
    at5 = load_system("peixoto-ex2", parameters={"rho": 5.0})
    assert at5.model().vertices.A[0, 1, 1] == pytest.approx(-0.25)
    with pytest.raises(ModelFileError, match="no parameter 'gamma' to override \\(known: rho\\)"):
        load_system("peixoto-ex2", parameters={"gamma": 1.0})
    # rho carries the paper's range [1, 21]: an override outside is refused, naming it
    assert (base.parameter_ranges["rho"].lower, base.parameter_ranges["rho"].upper) == (1.0, 21.0)
    assert load_system("peixoto-ex2", parameters={"rho": 21.0}).parameters == {"rho": 21.0}
    with pytest.raises(ModelFileError, match=r"parameters\.rho: override 21\.5 is outside its declared range "
                                             r"\[1, 21\]"):
        load_system("peixoto-ex2", parameters={"rho": 21.5})
    # a study beyond the range says so
    beyond = load_system("peixoto-ex2", parameters={"rho": 30.0}, allow_outside_range=True)
    assert beyond.model().vertices.A[0, 1, 1] == pytest.approx(-1.5)
    # the same from text
    from lpvest.systems._catalog import find_system

    text = find_system("peixoto-ex2").read_text(encoding="utf-8")
    with pytest.raises(ModelFileError, match=r"parameters\.rho: override 30 is outside"):
        loads_system(text, parameters={"rho": 30.0})
    assert loads_system(text, parameters={"rho": 30.0}, allow_outside_range=True).parameters == {"rho": 30.0}


RANGED = """
[system]
name = "ranged"
title = "parameters with ranges"

[parameters]
k = { value = 0.5, lower = 0.0, description = "a gain" }
m = 2.0

[scheduling]
names = ["p"]
lower = [-1.0]
upper = [1.0]

[models.m]
type = "affine"
A = [["0.5*k"]]
C = [[1.0]]
Q = [[0.1]]
R = [["0.01*m"]]
"""


@pytest.mark.parametrize(("old", "new", "message"), [
    ("value = 0.5, ", "", r"parameters\.k\.value: missing \(expected a number or formula\)$"),
    ("value = 0.5", "value = -1", r"parameters\.k\.value: -1 is outside its declared range \[0, inf\]"),
    ("lower = 0.0", "lower = 1.0, upper = 0.0", r"parameters\.k: lower 1 is above upper 0"),
    ("lower = 0.0", "lower = 0.0, step = 1",
     r"parameters\.k\.step: unknown key \(expected one of: description, lower, upper, value\)$"),
    ("lower = 0.0", 'lower = "x"', r"parameters\.k\.lower: "),
])
def test_ranged_parameters_are_checked(tmp_path, old, new, message):
    path = _write(tmp_path, RANGED.replace(old, new, 1))
    with pytest.raises(ModelFileError, match=f"^{path}: {message}"):
        load_system(path)


def test_ranged_parameters_survive_a_round_trip(tmp_path):
    system = load_system(_write(tmp_path, RANGED))
    assert system.parameters == {"k": 0.5, "m": 2.0}
    assert system.parameter_ranges["k"].lower == 0.0 and system.parameter_ranges["k"].upper is None
    again = loads_system(dump_system(system))
    assert again.parameter_ranges == system.parameter_ranges and again.parameters == system.parameters


GOOD = """
[system]
name = "user"
title = "a user's model"

[scheduling]
names = ["p"]
lower = [-1.0]
upper = [1.0]

[models.m]
type = "affine"
A = { "1" = [[0.5, 0.1], [0.0, 0.4]], p = [[0.1, 0.0], [0.0, -0.1]] }
C = [[1.0, 0.0]]
Q = [[0.1, 0.0], [0.0, 0.1]]
R = [[0.01]]
"""


def _write(tmp_path, text):
    path = tmp_path / "user.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_users_own_file_loads(tmp_path):
    system = load_system(_write(tmp_path, GOOD))
    m = system.model()
    assert isinstance(m, AffineLPV)
    np.testing.assert_allclose(m.at([1.0]).A, [[0.6, 0.1], [0.0, 0.3]])
    assert (m.nx, m.nu, m.ny, m.nw, m.nv) == (2, 0, 1, 2, 1)


# (replacement in GOOD, expected message after "<file>: ")
ERRORS = [
    ('R = [[0.01]]', 'R = [[0.01]]\nP0 = [[1.0, 2.0], [2.0, 1.0]]',
     "models.m: P0 is not positive semidefinite: smallest eigenvalue -1"),
    ('Q = [[0.1, 0.0], [0.0, 0.1]]', 'Q = [[0.1, 0.0], [0.0, 0.1], [0.0, 0.0]]',
     r"models.m: Q has shape \(3, 2\); expected a square matrix"),
    ('Q = [[0.1, 0.0], [0.0, 0.1]]', 'Q = [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]]',
     r"models.m: G has shape \(2, 2\); expected \(2, 3\)"),
    ('Q = [[0.1, 0.0], [0.0, 0.1]]', 'Q = [[0.1, 0.2], [0.2, 0.1]]',
     "models.m: Q is not positive definite: smallest eigenvalue -0.1"),
    ('Q = [[0.1, 0.0], [0.0, 0.1]]', 'Q = [[0.1, 0.05], [0.0, 0.1]]',
     "models.m: Q is not symmetric"),
    ('R = [[0.01]]', 'R = [[0.01]]\nS = [[1.0], [0.0]]',
     r"models.m: the joint noise covariance \[\[Q, S\], \[S\^T, R\]\] is not positive definite"),
    ('C = [[1.0, 0.0]]', 'C = [[1.0, 0.0], [1.0]]',
     r"models.m.C: rows have different lengths \[1, 2\]; expected equal"),
    ('C = [[1.0, 0.0]]', 'C = [[1.0, "x"]]',
     r"models.m.C\[1,2\]: formula 'x' must be a constant here but uses the variable x"),
    ('C = [[1.0, 0.0]]', 'C = [[1.0, true]]',
     r"models.m.C\[1,2\]: expected a number or formula, found a boolean \(true\)$"),
    ('C = [[1.0, 0.0]]', 'C = [[1.0, 0.0]]\nF = [[1.0]]',
     "models.m.F: unknown key \\(expected one of: A, B, C, Cz, D, G, H, P0, Q, R, S, basis, bounds, title, "),
    ('R = [[0.01]]', '', r"models.m.R: missing \(expected a matrix\)$"),
    ('type = "affine"', 'type = "afine"', "models.m.type: unknown model type 'afine'"),
    ('p = [[0.1, 0.0], [0.0, -0.1]]', 'q = [[0.1, 0.0], [0.0, -0.1]]',
     r"models.m.basis: formula 'q' uses unknown name 'q' \(known: p\)"),
    ('lower = [-1.0]', 'lower = [2.0]', "scheduling: scheduling range of p: lower bound 2 exceeds upper bound 1"),
    ('lower = [-1.0]', 'lower = [-1.0, 0.0]', r"scheduling.lower: has 2 entries; expected 1 \(one per name\)"),
    ('names = ["p"]', 'names = ["2p"]', "scheduling: scheduling name '2p' is not a valid identifier"),
    ('names = ["p"]', 'names = "p"', "scheduling.names: expected a list of strings, found a string"),
    ('title = "a user\'s model"', '', r"system.title: missing \(expected a string\)$"),
    ('[models.m]', '[models.m]\nbasis = ["sin(p"]', r"models.m.basis: formula 'sin\(p' is not valid"),
]


@pytest.mark.parametrize(("old", "new", "message"), ERRORS, ids=[e[2][:40] for e in ERRORS])
def test_validation_errors_name_file_and_field(tmp_path, old, new, message):
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ModelFileError, match=f"^{path}: {message}") as info:
        load_system(path)
    assert "\n" not in str(info.value)


def test_invalid_toml_syntax(tmp_path):
    path = _write(tmp_path, GOOD.replace("R = [[0.01]]", "R = [[0.01]"))
    with pytest.raises(ModelFileError, match=f"^{path}: not valid TOML: "):
        load_system(path)


def test_missing_file_and_unknown_example(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ModelFileError, match="^nothere.toml: no such model file$"):
        load_system("nothere.toml")
    # a long path is shortened (errors.shorten), whatever pytest's temporary folder is
    missing = tmp_path / "nothere.toml"
    with pytest.raises(ModelFileError, match=f"^{re.escape(shorten(str(missing), 120))}: no such model file$"):
        load_system(missing)
    with pytest.raises(ModelFileError, match="no example system 'peixoto-ex9' \\(examples: cox-toth-ex1, "):
        load_system("peixoto-ex9")


POLY = """
[system]
name = "poly"
title = "t"
[scheduling]
names = ["theta"]
lower = [-1.0]
upper = [1.0]
[models.plant]
type = "polytopic"
[models.plant.map]
kind = "formulas"
alpha = ["(1 - theta)/2", "(1 + theta)/2"]
[[models.plant.vertex]]
A = [[0.5]]
[[models.plant.vertex]]
A = [[0.1]]
[models.plant.common]
Bw = [[1.0]]
Cz = [[1.0]]
Dz = [[0.0]]
Cy = [[1.0]]
Dy = [[1.0]]
[models.plant.affine]
Bw = [[1.0]]
Cz = [[1.0]]
Dz = [[0.0]]
Cy = [[1.0]]
Dy = [[1.0]]
[models.plant.affine.A]
"1" = [[0.3]]
theta = [[-0.2]]
"""

POLY_ERRORS = [
    ('theta = [[-0.2]]', 'theta = [[0.2]]',
     "models.plant.vertex: A at the vertices, combined by the map, differs from the affine form by 0.4"),
    ('alpha = ["(1 - theta)/2", "(1 + theta)/2"]', 'alpha = ["(1 - theta)/2", "(1 + theta)/3"]',
     "models.plant.map.alpha: simplex map at theta = 1: alpha is not on the unit simplex: its entries sum to 0.6666"),
    ('alpha = ["(1 - theta)/2", "(1 + theta)/2"]', 'alpha = ["1 - theta", "theta"]',
     r"models.plant.map.alpha: simplex map at theta = -1: alpha is not on the unit simplex: alpha\[2\] = -1 < 0"),
    ('[[models.plant.vertex]]\nA = [[0.1]]', '[[models.plant.vertex]]\nA = [[0.1]]\nBw = [[2.0]]',
     r"models.plant.vertex\[2\].Bw: Bw is also given in \[models.plant.common\]"),
    ('Dy = [[1.0]]\n[models.plant.affine]', '[models.plant.affine]',
     r"models.plant.vertex\[1\]: missing Dy \(give it here or in \[models.plant.common\]\)"),
    ('[[models.plant.vertex]]\nA = [[0.1]]', '[[models.plant.vertex]]\nA = [[0.1, 0.0]]',
     r"models.plant.vertex: A has different shapes at the vertices: \[\(1, 1\), \(1, 2\)\]"),
    ('kind = "formulas"', 'kind = "table"', "models.plant.map.kind: unknown map kind 'table'"),
]


def test_polytopic_file_loads_and_is_consistent(tmp_path):
    plant = load_system(_write(tmp_path, POLY)).model()
    np.testing.assert_allclose(plant.vertices.A[:, 0, 0], [0.5, 0.1])


@pytest.mark.parametrize(("old", "new", "message"), POLY_ERRORS, ids=[e[2][:40] for e in POLY_ERRORS])
def test_polytopic_errors(tmp_path, old, new, message):
    assert old in POLY
    path = _write(tmp_path, POLY.replace(old, new, 1))
    with pytest.raises(ModelFileError, match=f"^{path}: {message}"):
        load_system(path)


def test_innovation_and_io_errors(tmp_path):
    base = load_system("cox-toth-ex1").path.read_text()
    path = _write(tmp_path, base.replace('K = [[1.0], [1.0]]', 'K = [[1.0]]'))
    with pytest.raises(ModelFileError, match=r"models.augmented: K has shape \(1, 1\); expected \(2, 1\)"):
        load_system(path)
    path = _write(tmp_path, base.replace('"(1 - shift(p, 1)) / shift(p, 1)"', '"(1 - shift(q, 1))"'))
    with pytest.raises(ModelFileError, match="models.minimal.K: K\\[1,1\\]: formula .* uses unknown name 'q'"):
        load_system(path)
    path = _write(tmp_path, base.replace('y = ["-p"]', 'y = ["-shift(p, 1)"]'))
    with pytest.raises(ModelFileError, match=r"models.io: y\[0\] = .*: coefficients depend on p_t only"):
        load_system(path)
    path = _write(tmp_path, base.replace("innovation_covariance = [[1.0]]", "innovation_covariance = [[-1.0]]", 1))
    with pytest.raises(ModelFileError, match="models.minimal: innovation covariance is not positive definite"):
        load_system(path)


# -- every malformed file is one line naming file and field (issue 12) -----------------------------

EX2 = (Path(__file__).resolve().parent.parent / "models" / "peixoto_ex2.toml").read_text()
A22 = r"models\.plant\.vertex\[1\]\.A\[2,2\]"
TRUNC = (Path(__file__).resolve().parent.parent / "models" / "cox_toth_truncation.toml").read_text()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # were ZeroDivisionError, OverflowError and a computation that never ended
        (EX2.replace('"-0.05*rho"', '"1/0"'), rf"{A22}: formula '1/0' divides by zero$"),
        (EX2.replace('"-0.05*rho"', '"10**400"'), rf"{A22}: formula '10\*\*400' overflows"),
        (EX2.replace('"-0.05*rho"', '"9**9**9"'), rf"{A22}: formula '9\*\*9\*\*9' overflows"),
        (EX2.replace('"-0.05*rho"', '"' + "+".join(["rho"] * 50_000) + '"'),
         r"models\.plant\.vertex\[1\]\.A\[2,2\]: formula 'rho\+rho.*' \(199,999 characters\) is too long"),
        # was LinAlgError from the definiteness check (an entry of -1e308), and 1e308 accepted
        (TRUNC.replace("Q = [[0.02,", "Q = [[-1e308,"),
         r"models\.plant\.Q\[1,1\]: -1e\+308 is too large: numbers in a model file are at most 1e\+100 in magnitude$"),
        (EX2.replace('"-0.05*rho"', "1e308"), r"models\.plant\.vertex\[1\]\.A\[2,2\]: 1e\+308 is too large"),
        (EX2.replace('"-0.05*rho"', "nan"), rf"{A22}: expected a finite number, found a number \(nan\)$"),
        (EX2.replace("rho = { value = 1.0,", "rho = { value = inf,"),
         r"parameters\.rho\.value: expected a finite number, found a number \(inf\)$"),
        (EX2.replace("\nrho = {", "\nt = {"), r"parameters\.t: 't' is a name formulas reserve"),
        # was RecursionError inside the TOML parser
        (EX2.replace('"-0.05*rho"', "[" * 500 + "1" + "]" * 500),
         r"not valid TOML: arrays or tables nested too deeply$"),
        # a 20,000-character value was echoed whole
        (EX2.replace('type = "polytopic"', 'type = "' + "x" * 20_000 + '"'),
         r"models\.plant\.type: unknown model type 'xxxx.*' \(20,000 characters\) \(expected one of"),
        (EX2.replace("[scheduling]", '[scheduling]\n"' + "k" * 5000 + '" = 1', 1),
         r"scheduling\.'kkkk.*' \(5,000 characters\): unknown key \(expected one of: lower, names, upper\)$"),
    ],
    ids=["1/0", "10**400", "9**9**9", "100k terms", "-1e308", "1e308", "nan", "inf parameter", "reserved name",
         "nested 500 deep", "long value", "long key"],
)
def test_malformed_values_are_one_short_line(tmp_path, text, message):
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(ModelFileError, match=f"^{path}: {message}") as info:
        load_system(path)
    assert "\n" not in str(info.value) and len(str(info.value)) <= 300 + len(str(path))


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (EX2.encode("utf-16"), r"not a TOML text file: byte 1 \(b'\\xff'\) is not UTF-8 \(the file is UTF-16; "
                               r"save it as UTF-8\)$"),
        (b"\x89PNG\r\n\x1a\n\x00\x00", r"not a TOML text file: byte 1 \(b'\\x89'\) is not UTF-8$"),
        (b"a = " + b"1" * 5000, r"not valid TOML: Exceeds the limit \(4300 digits\)"),
    ],
    ids=["utf-16", "binary", "5000 digits"],
)
def test_files_that_are_not_toml_text(tmp_path, raw, message):
    # were UnicodeDecodeError (modelfile.py read UTF-8 and caught only OSError) and ValueError
    path = tmp_path / "m.toml"
    path.write_bytes(raw)
    with pytest.raises(ModelFileError, match=f"^{path}: {message}"):
        load_system(path)


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "m.toml"
    path.write_bytes(b"\xef\xbb\xbf" + EX2.encode())
    assert load_system(path).name == "peixoto-ex2"


def test_models_are_named_system_slash_key():
    assert load_system("peixoto-ex1").model().name == "peixoto-ex1/plant"
    assert load_system("cox-toth-ex1").model("io").name == "cox-toth-ex1/io"


def test_a_model_unstable_along_the_schedule_is_an_error_not_inf(tmp_path):
    # entries of 1e100 are accepted, but the simulation leaves the floating-point range: a clear error
    from lpvest.core._errors import NumericalError
    from lpvest.experiments._simulate import simulate_system

    path = tmp_path / "m.toml"
    path.write_text(EX2.replace('"-0.05*rho"', "1e100"))
    with pytest.raises(NumericalError, match=r"^simulating peixoto-ex2 / model plant: y is -?inf at k = 15 "
                                             r"\(the model is unstable along this schedule"):
        simulate_system(load_system(path), steps=20)


def test_save_system_creates_the_folder_and_names_a_file_it_cannot_write(tmp_path):
    from lpvest import OutputError, save_system

    system = load_system("peixoto-ex1")
    path = save_system(system, tmp_path / "new" / "folder" / "ex1.toml")
    assert load_system(path).model().n_vertices == 2
    (tmp_path / "a-file").write_text("x")
    with pytest.raises(OutputError, match=r"cannot write the model file .*ex1\.toml"):
        save_system(system, tmp_path / "a-file" / "ex1.toml")
