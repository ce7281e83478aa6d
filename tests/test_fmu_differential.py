"""Random FMI call sequences, the same on the Python and the native FMU of a role.

Two reviews found host crashes and false fmi2OK statuses in code whose inputs had
been fuzzed file by file (stop 35): what broke was the order of calls, not one
value. Here hypothesis draws a sequence of calls (the initialization calls in any
order, setters and getters of every type on any value reference, steps at the
next sample or not, FMU states taken, restored, serialized and freed, reset and
terminate) and runs it on both backends of one role, in this process through
fmpy. The two must answer every call with the same status and log the same
messages; the values they return must agree, and a value read with fmi2OK must be
finite. A difference is a defect of one of them (docs/fmus.md: the native FMUs
are the Python FMUs' behaviour in C), and hypothesis shrinks it to the shortest
sequence that shows it.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.fmu_driver import Driver

SCALE = float(os.environ.get("LPVEST_PROPERTY_SCALE", "1"))

#: one FMU of every native role, with parameters of every type
ROLES = ["PeixotoEx1Plant", "IoDemoPlant", "PeixotoEx1Scheduler", "CoxTothTruncationSource",
         "CoxTothTruncationKalman", "CoxTothTruncationTruncatedKalman", "PeixotoEx1HinfPD"]

#: Reals: in and out of the ports' ranges, zero of both signs, not finite
REALS = [0.0, -0.0, 0.25, 0.5, -0.5, 1.0, -1.0, 2.0, 3.0, 1e3, math.nan, math.inf, -math.inf]
INTEGERS = [0, 1, 2, 3, -1, 200, 2**31 - 1]
STRINGS = ["", "theorem", "steady-state", "zero", "constant", "sinusoid", "decaying", "gaussian", "table",
           "0 1; 1 2", "0 1 2; 1 2 3", "0 nan", "x", "%s%n"]
VALUES: dict[str, list[object]] = {"Real": list(REALS), "Integer": list(INTEGERS), "Boolean": [False, True],
                                   "String": list(STRINGS)}
UNKNOWN_VR = 999_999
SLOTS = 3

#: the calls: (name, arguments drawn independently of the FMU)
CALLS = st.one_of(
    # a start time; a stop time or none (a step past it, NaN or before the start: refused)
    st.tuples(st.just("setup"), st.sampled_from([0.0, 1.0, -2.0, math.nan]),
              st.sampled_from([None, None, None, 3.0, 0.5, -3.0, math.inf, math.nan])),
    st.tuples(st.just("enter")),
    st.tuples(st.just("exit")),
    st.tuples(st.just("terminate")),
    st.tuples(st.just("reset")),
    st.tuples(st.just("set"), st.integers(0, 10**6), st.sampled_from(["Real", "Integer", "Boolean", "String"]),
              st.integers(0, 10**6)),
    st.tuples(st.just("get"), st.integers(0, 10**6), st.sampled_from(["Real", "Integer", "Boolean", "String"])),
    # several elements in one call, the same one twice possibly: a bad one among good ones
    st.tuples(st.just("set_many"), st.sampled_from(["Real", "Integer", "Boolean", "String"]),
              st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 10**6)), min_size=2, max_size=4)),
    st.tuples(st.just("get_many"), st.sampled_from(["Real", "Integer", "Boolean", "String"]),
              st.lists(st.integers(0, 10**6), min_size=2, max_size=4)),
    # a call of no elements (nvr = 0): changes nothing (FMI 2.0, 2.1.7)
    st.tuples(st.just("set_many"), st.sampled_from(["Real", "Integer", "Boolean", "String"]), st.just([])),
    st.tuples(st.just("get_many"), st.sampled_from(["Real", "Integer", "Boolean", "String"]), st.just([])),
    st.tuples(st.just("outputs")),
    # a step from the time the FMU is at (offset 0) or not, of whole samples or not
    st.tuples(st.just("step"), st.sampled_from([0.0, 0.0, 0.0, 0.0, 1.0, -1.0, 0.5]),
              st.sampled_from([1.0, 1.0, 1.0, 2.0, 3.0, 0.5, 0.0, -1.0, math.inf])),
    st.tuples(st.just("get_state"), st.integers(0, SLOTS - 1)),
    st.tuples(st.just("set_state"), st.integers(0, SLOTS - 1)),
    st.tuples(st.just("serialize"), st.integers(0, SLOTS - 1)),
    st.tuples(st.just("free_state"), st.integers(0, SLOTS - 1)),
)


class _Run:
    """One instance and the trace of what it answered."""

    def __init__(self, path) -> None:  # noqa: ANN001
        self.d = Driver(path)
        md = self.d.md
        self.ts = float(md.defaultExperiment.stepSize)
        self.variables = sorted(md.modelVariables, key=lambda v: v.valueReference)
        self.outputs = [v.valueReference for v in self.variables if v.causality == "output" and v.type == "Real"]
        self.time = 0.0
        self.states: list[object | None] = [None] * SLOTS
        self.seen = 0

    def _variable(self, pick: int, kind: str) -> tuple[int, str]:
        """A variable of the kind (most often), any variable, or an unknown reference."""
        if pick % 10 == 9:
            return UNKNOWN_VR, kind
        same = [v for v in self.variables if v.type == kind]
        pool = same if same and pick % 10 < 7 else self.variables
        v = pool[(pick // 10) % len(pool)]
        return v.valueReference, kind

    def call(self, call: tuple) -> tuple:
        """Do ``call``; what it returned and the messages it logged (warnings and worse)."""
        f, d = call[0], self.d
        value: object = None
        if f == "setup":
            stop = call[2] if len(call) > 2 else None
            status = d.raw("fmi2SetupExperiment", 0, 0.0, call[1], int(stop is not None), stop or 0.0)
            if status == 0:
                self.time = call[1]
        elif f == "enter":
            status = d.raw("fmi2EnterInitializationMode")
        elif f == "exit":
            status = d.raw("fmi2ExitInitializationMode")
        elif f == "terminate":
            status = d.raw("fmi2Terminate")
        elif f == "reset":
            status = d.raw("fmi2Reset")
        elif f == "set":
            vr, kind = self._variable(call[1], call[2])
            pick = call[3]
            pool = VALUES[kind]
            status = d.status(getattr(d.fmu, f"set{kind}"), [vr], [pool[pick % len(pool)]])
        elif f == "get":
            vr, kind = self._variable(call[1], call[2])
            status, value = self._get(kind, [vr])
        elif f == "set_many":
            kind, pool = call[1], VALUES[call[1]]
            vrs = [self._variable(pick, kind)[0] for pick, _ in call[2]]
            status = d.status(getattr(d.fmu, f"set{kind}"), vrs, [pool[v % len(pool)] for _, v in call[2]])
        elif f == "get_many":
            status, value = self._get(call[1], [self._variable(pick, call[1])[0] for pick in call[2]])
        elif f == "outputs":
            status, value = self._get("Real", self.outputs)
        elif f == "step":
            t, h = self.time + call[1] * self.ts, call[2] * self.ts
            status = d.step(t, h)
            if status == 0:
                self.time = t + h
        elif f == "get_state":
            status, value = self._state(lambda: d.fmu.getFMUstate(), call[1])
        elif f == "set_state":
            state = self.states[call[1]]
            status = d.status(d.fmu.setFMUstate, state) if state is not None else -1
        elif f == "serialize":
            state = self.states[call[1]]
            if state is None:
                status = -1
            else:
                status, value = self._state(lambda: d.fmu.deSerializeFMUstate(d.fmu.serializeFMUstate(state)),
                                            call[1])
        else:  # free_state
            state = self.states[call[1]]
            status = d.status(d.fmu.freeFMUstate, state) if state is not None else -1
            self.states[call[1]] = None
        new = [(s, m.split("] ", 1)[-1]) for s, _, m in d.messages[self.seen:] if s >= 1]
        self.seen = len(d.messages)
        return status, value, new

    def _get(self, kind: str, vrs: list[int]) -> tuple[int, object]:
        from fmpy.fmi1 import FMICallException

        try:
            return 0, list(getattr(self.d.fmu, f"get{kind}")(vrs))
        except FMICallException as exc:
            return int(exc.status), None

    def _state(self, take, slot: int) -> tuple[int, object]:  # noqa: ANN001
        from fmpy.fmi1 import FMICallException

        try:
            state = take()
        except FMICallException as exc:
            return int(exc.status), None
        old = self.states[slot]
        if old is not None:
            self.d.fmu.freeFMUstate(old)
        self.states[slot] = state
        return 0, None

    def free(self) -> None:
        for slot, state in enumerate(self.states):
            if state is not None:
                self.d.status(self.d.fmu.freeFMUstate, state)
                self.states[slot] = None
        self.d.free()


def _same_values(a: object, b: object) -> bool:
    """Equal, but Reals within a rounding allowance: the backends compute the same
    recursions in another order (tests/test_native_fmus.py bounds each role's
    difference from the library by its rounding analysis, about 1e-13 of the
    scale over such short runs); a relative 1e-9 is far above that and far
    below what a wrong state, a stale output or a skipped sample gives (order 1)."""
    if not isinstance(a, list) or not isinstance(b, list) or len(a) != len(b):
        return a == b
    for x, y in zip(a, b, strict=True):
        if isinstance(x, float) and isinstance(y, float):
            if math.isnan(x) or math.isnan(y):
                if not (math.isnan(x) and math.isnan(y)):
                    return False
            elif x != y and abs(x - y) > 1e-9 * max(1.0, abs(x), abs(y)):
                return False
        elif x != y:
            return False
    return True


def _not_finite_with_ok(answer: tuple) -> bool:
    status, value, _ = answer
    return status == 0 and isinstance(value, list) and any(
        isinstance(x, float) and not np.isfinite(x) for x in value)


@pytest.mark.parametrize("name", ROLES)
def test_a_call_of_no_elements_changes_nothing_on_either_backend(fmus, native_fmus, name):
    """fmi2Set* of no elements (nvr = 0) sets nothing (FMI 2.0, 2.1.7): the outputs held
    after a step stay what they were. The Python FMU's fast path for inputs took an empty
    call for "every input set" and computed the next sample's feedthrough outputs, with
    fmi2OK."""
    for path in (fmus[name], native_fmus[name]):
        run = _Run(path)
        try:
            inputs = [v.valueReference for v in run.variables if v.causality == "input" and v.type == "Real"]
            for call in (("setup", 0.0), ("enter",), ("exit",), ("step", 0.0, 1.0)):
                assert run.call(call)[0] == 0, (name, call)
            if inputs:  # inputs of the next sample, then a step to it: outputs held from then on
                assert run.d.status(run.d.fmu.setReal, inputs, [0.5] * len(inputs)) == 0
                assert run.call(("step", 0.0, 1.0))[0] == 0
            before = run.call(("outputs",))
            for kind in ("Real", "Integer", "Boolean", "String"):
                assert run.call(("set_many", kind, []))[::2] == (0, []), (name, kind)
                assert run.call(("get_many", kind, [])) == (0, [], []), (name, kind)
            assert run.call(("outputs",)) == before, name
        finally:
            run.free()


@pytest.mark.parametrize("name", ROLES)
def test_random_call_sequences_get_the_same_answers_from_both_backends(fmus, native_fmus, name):
    """Both backends of ``name`` answer every call of a random sequence alike: the
    status, the messages and the values (Reals within rounding); no Real is read
    as not finite with fmi2OK."""

    @settings(max_examples=max(1, int(60 * SCALE)))
    @given(st.lists(st.one_of(CALLS, st.just(("init",))), min_size=1, max_size=40))
    def check(calls: list[tuple]) -> None:
        runs = [_Run(fmus[name]), _Run(native_fmus[name])]
        try:
            done: list[str] = []
            for call in calls:
                if call == ("init",):  # the usual start, so that most sequences reach steps
                    call_list = [("setup", 0.0), ("enter",), ("exit",)]
                else:
                    call_list = [call]
                for c in call_list:
                    python, native = (r.call(c) for r in runs)
                    done.append(repr(c))
                    where = f"{name}, after {' -> '.join(done)}"
                    assert python[0] == native[0] and python[2] == native[2], \
                        f"{where}: Python answered {python}, native {native}"
                    assert _same_values(python[1], native[1]), f"{where}: Python read {python[1]}, native {native[1]}"
                    assert not _not_finite_with_ok(python), f"{where}: read with fmi2OK: {python[1]}"
        finally:
            for r in runs:
                r.free()

    check()
