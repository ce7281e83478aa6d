"""Test FMU: y = slope * t (no inputs)."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

# pythonfmu 0.7's findClass executes this file again at every instantiation (with fresh
# locals) and then releases a reference to this namespace that it never took: take it for
# it, as lpvest's FMUs do (lpvest.fmi._bundle), or the namespace is freed while in use.
if locals() is not globals():
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))


class Ramp(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.slope = 1.0
        self.time = 0.0
        self.register_variable(Real("slope", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, getter=lambda: self.slope * self.time))

    def do_step(self, current_time, step_size):
        self.time = current_time + step_size
        return True
