"""Test FMU: fails in doStep once t >= fail_at."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status

# pythonfmu 0.7's findClass executes this file again at every instantiation (with fresh
# locals) and then releases a reference to this namespace that it never took: take it for
# it, as lpvest's FMUs do (lpvest.fmi._bundle), or the namespace is freed while in use.
if locals() is not globals():
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))


class Failing(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.fail_at = 3.0
        self.u = 0.0
        self.register_variable(Real("fail_at", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output, getter=lambda: self.u))

    def do_step(self, current_time, step_size):
        if current_time >= self.fail_at:
            self.log("deliberate failure for the test", status=Fmi2Status.warning)
            return False
        return True
