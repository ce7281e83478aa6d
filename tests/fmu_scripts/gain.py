"""Test FMU: y[i] = k * u[i] (direct feedthrough), two elements."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

# pythonfmu 0.7's findClass executes this file again at every instantiation (with fresh
# locals) and then releases a reference to this namespace that it never took: take it for
# it, as lpvest's FMUs do (lpvest.fmi._bundle), or the namespace is freed while in use.
if locals() is not globals():
    import ctypes

    ctypes.pythonapi.Py_IncRef(ctypes.py_object(globals()))


class Gain(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 2.0
        self.u1 = 0.0
        self.u2 = 0.0
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("u[1]", causality=Fmi2Causality.input, getter=lambda: self.u1,
                                    setter=lambda v: setattr(self, "u1", v)))
        self.register_variable(Real("u[2]", causality=Fmi2Causality.input, getter=lambda: self.u2,
                                    setter=lambda v: setattr(self, "u2", v)))
        self.register_variable(Real("y[1]", causality=Fmi2Causality.output, getter=lambda: self.k * self.u1))
        self.register_variable(Real("y[2]", causality=Fmi2Causality.output, getter=lambda: self.k * self.u2))

    def do_step(self, current_time, step_size):
        return True
