"""linknet's own integrators, driven through the public API of docs/architecture.md (Simulator.advance)."""
from __future__ import annotations

import inspect

from .base import Method, RunResult, Timer

MAX_STEPS = 10**9


def linknet_available() -> tuple[bool, str]:
    try:
        import linknet_core as ln
        ln.Simulator  # noqa: B018
        return True, ""
    except Exception as e:  # the core may be mid-edit: say why, do not crash the whole benchmark
        return False, f"linknet_core not importable ({type(e).__name__}: {e})"


def linknet_method_names() -> list[str]:
    ok, _ = linknet_available()
    if not ok:
        return []
    from linknet_core.integrators import METHODS
    return list(METHODS)


class LinknetMethod(Method):
    family = "linknet"

    def __init__(self, method: str):
        from linknet_core.integrators import METHODS
        cls = METHODS[method]
        self.method = method
        self.name = f"linknet-{method}"
        self.knob = "rtol" if cls.adaptive else "dt"
        self.order = cls.order

    def available(self):
        return linknet_available()

    def run(self, spec, t_end, knob):
        import linknet_core as ln
        with Timer() as setup:
            scene = ln.Scene.from_dict(spec.to_dict())
            kwargs = {self.knob: knob}
            params = inspect.signature(ln.Simulator).parameters
            for name in ("max_steps_per_call", "max_steps"):   # no step cap short of the run itself
                if name in params:
                    kwargs[name] = MAX_STEPS
                    break
            if "error_estimate" in params:  # the integration alone, as the peers' (the estimate's cost:
                kwargs["error_estimate"] = False  # benchmarks/accuracy.py)
            sim = ln.Simulator(scene, method=self.method, **kwargs)
            # warm-up on a throwaway simulator: one-time compilation (numba/codegen caches) is setup, as
            # OpenMM's Context creation and MuJoCo's model compilation are for the peers
            warm = ln.Simulator(scene, method=self.method, **kwargs)
            warm.advance(min(knob, t_end) if self.knob == "dt" else 1e-3 * t_end)
        with Timer() as tm:
            sim.advance(t_end)
        st = sim.state
        info = {}
        integ = getattr(sim, "integrator", None)
        stats = getattr(integ, "stats", None)
        steps = int(getattr(stats, "steps", 0) or 0)
        if stats is not None and hasattr(stats, "as_dict"):
            info = stats.as_dict()
        return RunResult(st.X.copy(), st.U.copy(), tm.seconds, setup.seconds, steps=steps, info=info)
