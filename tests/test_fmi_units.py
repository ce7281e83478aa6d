"""Numpy-only FMU pieces: names, state serialization, spec parameters, registry."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest.fmi._naming import element_names, fmu_name, parse_element
from lpvest.fmi._parameters import Parameter
from lpvest.fmi._registry import EstimatorKind, estimator_kinds, resolve
from lpvest.fmi._state import decode_state, encode_state


def test_structured_names_are_one_based_and_row_major():
    assert element_names("P", (2, 3))[:4] == ["P[1,1]", "P[1,2]", "P[1,3]", "P[2,1]"]
    assert element_names("tau", ()) == ["tau"]
    assert parse_element("P[2,3]") == ("P", (2, 3)) and parse_element("w.std[1]") == ("w.std", (1,))
    assert [fmu_name(n) for n in ("peixoto-ex1", "cox-toth-ex1", "sridhar-ltv", "9x")] == [
        "PeixotoEx1", "CoxTothEx1", "SridharLtv", "Model9x"]


def test_state_round_trip_is_bit_for_bit():
    rng = np.random.default_rng(5)
    rng.standard_normal(3)
    state = {"P": np.array([[1.0, np.nan], [np.inf, -0.0]]), "k": 7, "flag": True, "name": "x",
             "rng": rng.bit_generator.state, "nested": {"t": (1, 2.5)}, "ints": np.arange(3)}
    back = decode_state(encode_state(state))
    assert back["P"].tobytes() == state["P"].tobytes() and back["ints"].dtype == state["ints"].dtype
    assert back["nested"]["t"] == (1, 2.5) and back["rng"] == state["rng"]
    again = np.random.default_rng()
    again.bit_generator.state = back["rng"]
    assert np.array_equal(again.standard_normal(4), rng.standard_normal(4))


def test_state_decoding_rejects_foreign_bytes():
    with pytest.raises(ValueError, match="not a serialized lpvest FMU state"):
        decode_state(b'{"format": "other"}')
    with pytest.raises(TypeError, match="cannot serialize a object"):
        encode_state({"x": object()})
    # one digit of an estimate changed (base64 of its bytes), a number changed, or cut short:
    # refused, never restored as another state
    good = encode_state({"x": np.array([1.0, 2.0]), "k": 3})
    at = good.index(b"__ndarray__") + len(b'__ndarray__": "') + 2
    for bad in (good[:at] + (b"B" if good[at:at + 1] != b"B" else b"C") + good[at + 1:],
                good.replace(b'"k": 3', b'"k": 4')):
        with pytest.raises(ValueError, match=r"it is damaged: its SHA-256 does not match"):
            decode_state(bad)
    with pytest.raises(ValueError, match="not a serialized lpvest FMU state: "):
        decode_state(good[:-3])


def test_parameter_types_follow_the_start_value():
    types = [Parameter(n, s).fmi_type for n, s in (("a", True), ("b", 3), ("c", 0.5), ("d", "s"), ("e", [1.0, 2.0]))]
    assert types == ["Boolean", "Integer", "Real", "String", "Real"]
    p = Parameter.from_json(Parameter("x0", [1.0, 2.0], minimum=0.0).to_json())
    assert p.shape == (2,) and p.minimum == 0.0


def test_registry_resolves_factories_and_selects_models():
    from lpvest import load_system

    kind = EstimatorKind("Kalman", "lpvest.core._signals:sample_signal", models=("affine",))
    assert resolve(kind.factory).__name__ == "sample_signal"
    assert not kind.applies_to(load_system("peixoto-ex1").model())
    assert all(isinstance(k, EstimatorKind) for k in estimator_kinds())
    with pytest.raises(ValueError, match="not of the form 'module:function'"):
        resolve("lpvest.core._signals")
