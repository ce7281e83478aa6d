"""Test FMU: fails in doStep once t >= fail_at."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status


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
