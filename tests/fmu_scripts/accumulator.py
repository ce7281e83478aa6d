"""Test FMU: y = x, x <- x + u at each step (no direct feedthrough, x(0) = x0)."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

# pythonfmu 0.7's findClass executes this file again at every instantiation (with fresh
# locals) and then releases a reference to this namespace that it never took: take it for
# it, as lpvest's FMUs do (lpvest.fmi._bundle), or the namespace is freed while in use.
if locals() is not globals():
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))


class Accumulator(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x0 = 1.0
        self.x = None
        self.u = 0.0
        self.register_variable(Real("x0", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output, getter=self._y))

    def _y(self):
        return self.x0 if self.x is None else self.x

    def do_step(self, current_time, step_size):
        self.x = self._y() + self.u
        return True
