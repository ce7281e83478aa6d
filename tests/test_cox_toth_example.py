"""Cox & Toth Example 1: (21a), (21b), (21c) are one system."""

import numpy as np
import pytest

from lpvest import NumericalError, load_system
from tests.tolerances import roundoff

pytestmark = pytest.mark.blas_sensitive  # numerical agreement: ./dev test runs it under a second BLAS kernel


@pytest.fixture(scope="module")
def system():
    return load_system("cox-toth-ex1")


def _signals(rng, T):
    # p bounded away from 0 (21b divides by p_{t+1}), both signs
    mag = rng.uniform(0.2, 1.0, T + 1)
    sign = np.where(rng.random(T + 1) < 0.5, -1.0, 1.0)
    return (mag * sign)[:, None], rng.standard_normal((T, 1)), rng.standard_normal((T, 1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_three_realizations_give_the_same_output(system, seed):
    rng = np.random.default_rng(seed)
    T = 200
    p, u, e = _signals(rng, T)
    y_io = system.model("io").simulate(p[:T], u, e=e).y
    y_min = system.model("minimal").simulate(p, u, e=e).y  # needs p_{T}
    y_aug = system.model("augmented").simulate(p[:T], u, e=e).y
    # three recursions for one map, per step sums of <= 4 products, over T steps;
    # |p| <= 1 so no growth: T steps' worth of rounding at most
    tol = roundoff(np.max(np.abs(y_io)) + np.max(np.abs(u)) + np.max(np.abs(e)), T, n=4)
    np.testing.assert_allclose(y_min, y_io, rtol=0, atol=tol)
    np.testing.assert_allclose(y_aug, y_io, rtol=0, atol=tol)


def test_io_form_written_out(system, rng):
    # oracle: (21a) written by hand
    T = 50
    p, u, e = _signals(rng, T)
    y = system.model("io").simulate(p[:T], u, e=e).y[:, 0]
    prev_y = prev_u = prev_e = 0.0
    for t in range(T):
        expect = -p[t, 0] * prev_y + p[t, 0] * prev_u + e[t, 0] + prev_e
        # one step from the library's own y_{t-1}: a sum of 4 terms in another order
        size = abs(p[t, 0] * prev_y) + abs(p[t, 0] * prev_u) + abs(e[t, 0]) + abs(prev_e)
        assert y[t] == pytest.approx(expect, abs=roundoff(size, 1, n=4))
        prev_y, prev_u, prev_e = y[t], u[t, 0], e[t, 0]


def test_minimal_realization_is_undefined_at_p_zero(system):
    p = np.array([[0.5], [0.0], [0.5]])
    with pytest.raises(NumericalError, match="the gain K is not finite at t=0"):
        system.model("minimal").simulate(p, np.zeros((2, 1)), e=np.ones((2, 1)))


def test_minimal_realization_needs_the_extra_sample(system):
    model = system.model("minimal")
    assert model.window == (0, 1)
    traj = model.simulate(np.full((11, 1), 0.5), np.zeros((10, 1)), rng=1)
    assert traj.y.shape == (10, 1)
