"""A test-only streaming estimator for the generic estimator FMU adapter.

A moving average over the last ``window`` samples of ``y`` (window filled from
the first sample on), its windowed second moment ``S = mean(y y^T)``, and the
scheduling it was given. It follows the step protocol of
``lpvest.core._protocol`` and is copied into the test FMU's resources, so it
is importable there as the top-level module ``fmu_movavg``.
"""

from __future__ import annotations

import numpy as np

from lpvest.core._errors import DimensionError, LpvestError
from lpvest.core._protocol import Port
from lpvest.core._validation import as_vector


class MovingAverage:
    """Moving average of y over ``window`` samples."""

    def __init__(self, ny: int, n_p: int, window: int) -> None:
        if window < 1 or window > 1000:
            # a user's estimator may explain at length: the FMU caps what it logs (lpvest.fmi._slave)
            raise LpvestError(f"window = {window} must lie in [1, 1000]. " + " ".join(
                f"(window {w}: {w} samples of y are averaged)" for w in range(1, 101)))
        self.ny, self.n_p, self.window = ny, n_p, int(window)
        self.reset()

    @property
    def input_ports(self) -> tuple[Port, ...]:
        return (Port("p", (self.n_p,), "scheduling"), Port("y", (self.ny,), "measurement"))

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return (Port("yhat", (self.ny,), "moving average"), Port("S", (self.ny, self.ny), "second moment"),
                Port("count", (), "samples in the window"))

    def reset(self) -> None:
        self._buf = np.zeros((self.window, self.ny))
        self._n = 0
        self._pos = 0

    def _window_with(self, y: np.ndarray) -> np.ndarray:
        buf = self._buf.copy()
        buf[self._pos] = y
        n = min(self._n + 1, self.window)
        return buf if n == self.window else np.roll(buf, -((self._pos + 1) % self.window), axis=0)[-n:]

    def outputs(self, inputs):  # noqa: ANN001, ANN201
        y = as_vector(inputs["y"], "y", self.ny)
        as_vector(inputs["p"], "p", self.n_p)
        win = self._window_with(y)
        return {"yhat": win.mean(axis=0), "S": win.T @ win / win.shape[0], "count": np.array(float(win.shape[0]))}

    def step(self, inputs):  # noqa: ANN001, ANN201
        out = self.outputs(inputs)
        self._buf[self._pos] = np.asarray(inputs["y"], dtype=float)
        self._pos = (self._pos + 1) % self.window
        self._n = min(self._n + 1, self.window)
        return out

    def get_state(self) -> dict:
        return {"buf": self._buf.copy(), "n": self._n, "pos": self._pos}

    def set_state(self, state) -> None:  # noqa: ANN001
        buf = np.asarray(state["buf"], dtype=float)
        if buf.shape != self._buf.shape:
            raise DimensionError(f"buf has shape {buf.shape}; expected {self._buf.shape}")
        self._buf, self._n, self._pos = buf.copy(), int(state["n"]), int(state["pos"])


def build(model, *, design=None, window: int = 4) -> MovingAverage:  # noqa: ANN001
    """The factory named in the test registration ``fmu_movavg:build``."""
    return MovingAverage(model.ny, model.space.dim, window)
