"""What the small component FMUs (PD controller, spring-damper) share: a parameter set out of range is
refused (fmi2Error) and remembered until corrected (the next doStep returns fmi2Discard), and errors reach the
host whether or not it instantiated with logging on."""
import math

from pythonfmu.enums import Fmi2Status


class GuardedComponent:
    """Mixin for an Fmi2Slave holding ``self.values`` (name -> float) and ``self.bad`` (name -> reason).

    ``OUTPUT_PREFIXES``: names that are outputs (refused when set); ``NON_NEGATIVE``: parameters that must be >= 0.
    """

    OUTPUT_PREFIXES: tuple = ()
    NON_NEGATIVE: tuple = ()

    def _set(self, name, value):
        if name.startswith(self.OUTPUT_PREFIXES):
            self._error(f"{name} is an output and cannot be set")
            return
        if not math.isfinite(value) or (name in self.NON_NEGATIVE and value < 0):
            rule = "finite, >= 0" if name in self.NON_NEGATIVE else "finite"
            self.bad[name] = f"= {value!r} is out of range ({rule})"
            self._error(f"{name} {self.bad[name]}; the next doStep is refused")
            return
        self.bad.pop(name, None)
        self.values[name] = float(value)

    def _error(self, msg, status=Fmi2Status.error):
        # the binary's front layer (fmu_src/pythonfmu_front) makes the worst status logged during a call the
        # call's status and hands errors to the host's logger, with loggingOn or not, under the host's name
        self.log(msg, status)

    def do_step(self, current_time, step_size):
        if self.bad:
            for name, why in self.bad.items():
                self._error(f"doStep refused: {name} {why}", Fmi2Status.discard)
            return False
        if not (math.isfinite(step_size) and step_size > 0):
            self._error(f"doStep refused: step size {step_size!r} must be > 0")
            return False
        return True
