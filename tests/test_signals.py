"""Test signals (lpvest.core._signals) and the Scheduler/Source components."""

from __future__ import annotations

import numpy as np
import pytest

from lpvest import load_system
from lpvest.core._rng import Stream
from lpvest.core._signals import (
    SchedulerComponent,
    SignalError,
    SignalGenerator,
    SignalSpec,
    SourceComponent,
    parse_table,
    sample_signal,
)
from tests.tolerances import roundoff

T = np.arange(0.0, 30.0, 0.5)


@pytest.mark.parametrize(("kind", "options", "formula"), [
    ("zero", {}, lambda t: 0 * t),
    ("constant", {"offset": 0.3}, lambda t: 0 * t + 0.3),
    ("sinusoid", {"amplitude": 2.0, "omega": 0.4, "phase": 0.1, "offset": -1.0},
     lambda t: -1.0 + 2.0 * np.sin(0.4 * t + 0.1)),
    ("decaying", {"amplitude": 1.0, "omega": 0.5, "decay": 0.1, "onset": 10.0},  # Peixoto et al., Section 4
     lambda t: np.where(t >= 10, np.sin(0.5 * t) * np.exp(-0.1 * t), 0.0)),
    ("table", {"table": "0 1; 10 -1; 20 3"}, lambda t: np.interp(t, [0, 10, 20], [1, -1, 3])),
])
def test_deterministic_kinds_follow_their_formula(kind, options, formula):
    got = sample_signal(SignalSpec.build(kind, 1, **options), T)[:, 0]
    # the same formula evaluated twice: sin / exp of arguments of size <= max |t|
    # (omega, decay <= 1) rounded once each, a few products with values <= 3
    size = 3.0 * (1.0 + float(np.max(np.abs(T))))
    np.testing.assert_allclose(got, formula(T), rtol=0, atol=roundoff(size, 3))


def test_gaussian_is_the_seeded_standard_normal_stream():
    spec = SignalSpec.build("gaussian", 2, std=[1.0, 3.0], offset=[0.0, 1.0], seed=7)
    got = sample_signal(spec, np.arange(50.0))
    expected = np.array([0.0, 1.0]) + np.array([1.0, 3.0]) * Stream(7).normal((50, 2))
    assert np.array_equal(got, expected)


def test_random_walk_steps_are_the_streams_uniforms():
    """``U(-1, 1) = -1 + 2 u`` with ``u`` the stream's uniforms (what numpy's
    ``uniform(-1, 1)`` computes from the same raw words)."""
    spec = SignalSpec.build("random", 2, rate=[1.0, 0.5], offset=0.0, seed=9)
    got = sample_signal(spec, np.arange(20.0))
    u = -1.0 + 2.0 * Stream(9).uniform((19, 2))
    assert np.array_equal(got[1:], np.cumsum(np.array([1.0, 0.5]) * 1.0 * u, axis=0))
    assert np.array_equal(u, np.random.default_rng(9).uniform(-1.0, 1.0, (19, 2)))


def test_random_walk_respects_rate_and_bounds(rng):
    spec = SignalSpec.build("random", 1, rate=2.0, offset=0.9, lower=-1.0, upper=1.0, seed=int(rng.integers(1000)))
    t = np.cumsum(rng.uniform(0.05, 0.3, 400))
    got = sample_signal(spec, t)[:, 0]
    assert got[0] == 0.9
    assert np.all(np.abs(np.diff(got)) <= 2.0 * np.diff(t) + 1e-15)
    assert got.min() >= -1.0 and got.max() <= 1.0
    lo, hi = spec.bounds()
    assert (lo[0], hi[0]) == (-1.0, 1.0)


def test_generator_state_round_trip_continues_identically():
    gen = SignalGenerator(SignalSpec.build("random", 3, rate=1.0, lower=-5, upper=5, seed=3))
    for t in range(1, 20):
        gen.advance(float(t))
    state = gen.get_state()
    first = [gen.advance(float(t)) for t in range(20, 30)]
    gen.set_state(state)
    assert np.array_equal(first, [gen.advance(float(t)) for t in range(20, 30)])


@pytest.mark.parametrize(("options", "message"), [
    ({"kind": "square"}, "kind = 'square' is not a signal kind"),
    ({"kind": "gaussian", "std": -1.0}, r"w.std\[1\] = -1 must be >= 0"),
    ({"kind": "sinusoid", "amplitude": [1.0, np.nan]}, r"w.amplitude\[2\] = nan is not finite"),
    ({"kind": "sinusoid", "omega": [1.0, 2.0, 3.0]}, r"w.omega has shape \(3,\); expected \(2,\)"),
    ({"kind": "random", "lower": 1.0, "upper": 0.0}, r"w.lower\[1\] = 1 exceeds w.upper\[1\] = 0"),
    ({"kind": "table", "table": "0 1 2; 0 3 4"}, "strictly increasing"),
    ({"kind": "table"}, "w.table is required"),
    ({"kind": "zero", "seed": -2}, "w.seed = -2 must be a non-negative integer"),
])
def test_bad_specifications_name_the_parameter(options, message):
    kind = options.pop("kind")
    with pytest.raises(SignalError, match=message):
        SignalSpec.build(kind, 2, prefix="w.", **options)


def test_parse_table_reports_the_row():
    with pytest.raises(SignalError, match=r"table row 2 \('1 2 3'\) has 3 numbers; expected 2"):
        parse_table("0 1; 1 2 3", 1)


@pytest.mark.parametrize(("text", "message"), [
    ("0\xa01; 1 2", r"row 1 \('0\\xa01'\) has 1 numbers"),  # NBSP: no blank
    ("0\x1c1; 1 2", r"row 1 \('0\\x1c1'\) has 1 numbers"),
    ("0 1\u3000; 1 2", r"row 1 \('0 1\\u3000'\) holds something that is not a number"),  # not stripped
    ("0 1;\x85 1 2", r"row 2 \('\\x85 1 2'\) has 3 numbers"),
    ("0 \u0661; 1 2", r"row 1 \('0 \u0661'\) holds something that is not a number"),  # an Arabic-Indic 1
    ("0 " + "1" * 301, r"holds something that is not a number"),
])
def test_a_tables_numbers_and_blanks_are_ascii_as_the_native_fmus_read_them(text, message):
    """str.strip, \\s and float() took Unicode's white space and digits, which the native
    runtime does not: the two backends answered such a table differently."""
    with pytest.raises(SignalError, match=message):
        parse_table(text, 1)
    times, values = parse_table(" 0\t1_0 ;\n1,2\v", 1)  # ASCII blanks, an underscore between digits
    assert times.tolist() == [0.0, 1.0] and values.ravel().tolist() == [10.0, 2.0]


def test_scheduler_rejects_a_signal_that_leaves_the_box():
    plant = load_system("peixoto-ex1").model()
    spec = SignalSpec.build("sinusoid", 1, amplitude=0.8, offset=0.5)
    with pytest.raises(SignalError, match=r"amplitude\[1\] = 0.8 with offset\[1\] = 0.5 takes p\[1\] \(theta\) "
                                          r"to \[-0.3, 1.3\], outside its declared range \[-1, 1\]"):
        SchedulerComponent(spec, plant.space, plant.simplex_map)
    with pytest.raises(SignalError, match="kind = 'gaussian'"):
        SchedulerComponent(SignalSpec.build("gaussian", 1, std=0.1), plant.space)


def test_scheduler_and_source_components_follow_the_timed_protocol():
    plant = load_system("peixoto-ex1").model()
    sched = SchedulerComponent(SignalSpec.build("sinusoid", 1, amplitude=1.0, omega=0.25), plant.space,
                               plant.simplex_map)
    sched.reset(0.0)
    out = [sched.step({}, dt=1.0)["alpha"] for _ in range(10)]
    p = np.sin(0.25 * np.arange(10))
    # sin(0.25 k), k < 10, then (1 -+ p) / 2: a few roundings of numbers of size <= 3.5
    np.testing.assert_allclose(out, np.c_[(1 - p) / 2, (1 + p) / 2], rtol=0, atol=roundoff(3.5, 2))
    src = SourceComponent({"w": SignalSpec.build("gaussian", 1, seed=2)})
    src.reset(0.0)
    state = src.get_state()
    a = [src.step({}, dt=1.0, t_end=float(k + 1))["w"] for k in range(5)]
    src.set_state(state)
    assert np.array_equal(a, [src.step({}, dt=1.0)["w"] for _ in range(5)])
