"""simulate's pool of numpy-reference Simulators (NumpyBackend.reusable): is a pooled run the run of a new
Simulator, bit for bit, and what does the pool save?

    python benchmarks/numpy_pool.py identity [NAME ...]   # every scene of models/, models/degenerate/, models/ropes/
                                                          # (or those whose path contains a NAME) x every method
    python benchmarks/numpy_pool.py cost                  # chain_10, rattle dt 1e-3: CPU time per Simulator and run

identity: for each scene and method, simulate on one scene object with no input force, then again with a held input
(the second run takes the first's Simulators from the pool, reset), against the same run on a fresh scene object:
every array of the result and its stats but the wall time. cost: CPU time (time.process_time), best of repeated
batches, interleaved: a new Simulator and its first advance against a reset of a used one and the same advance;
then simulate with the pool on and off. Writes nothing.
"""
from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

import linknet_core as ln
from linknet_core.simulator.numpy_backend import NumpyBackend

MODELS = Path(__file__).resolve().parents[1] / "models"
FIELDS = ("t", "X", "U", "T", "energy", "residual", "velocity_residual", "kinetic", "error_estimate")


def _same(a: ln.Result, b: ln.Result) -> bool:
    strip = lambda stats: {k: v for k, v in stats.items() if k != "wall_time"}  # noqa: E731
    arrays = all((getattr(a, f) is None and getattr(b, f) is None)
                 or getattr(a, f).tobytes() == getattr(b, f).tobytes() for f in FIELDS)
    return arrays and repr(strip(a.stats)) == repr(strip(b.stats))


def identity(names: list[str]) -> int:
    warnings.simplefilter("ignore")
    specs = [{"method": n, "rtol": 1e-6} if c.adaptive else {"method": n, "dt": 1e-3} for n, c in ln.METHODS.items()]
    paths = sorted(MODELS.glob("*.json")) + sorted(MODELS.glob("degenerate/*.json")) + sorted(MODELS.glob("ropes/*.json"))
    paths = [p for p in paths if not names or any(n in str(p) for n in names)]
    cases = differ = 0
    for path in paths:
        try:
            scene = ln.load_scene(path)
        except ln.LinknetError:
            continue
        push = np.zeros((scene.K, 3))
        push[-1] = (0.3, 0.1, 0.0)
        for spec in specs:
            run = dict(n_out=6, backend="numpy", progress=False, **spec)
            try:
                fresh = ln.simulate(ln.load_scene(path), 0.01, forces=push, **run)
            except ln.LinknetError:  # refused (hypothesis (35), a step the motions do not allow): nothing to pool
                continue
            ln.simulate(scene, 0.01, **run)
            pooled = ln.simulate(scene, 0.01, forces=push, **run)
            cases += 1
            if not _same(fresh, pooled):
                differ += 1
                print(f"DIFFERS: {path.relative_to(MODELS)} {spec}")
    print(f"{cases} cases, {differ} differ")
    return 1 if differ else 0


def _cpu_us(f, n: int) -> float:
    start = time.process_time()
    for _ in range(n):
        f()
    return (time.process_time() - start) / n * 1e6


def cost() -> int:
    warnings.simplefilter("ignore")
    scene = ln.load_scene(MODELS / "chain_10.json")
    kw = dict(method="rattle", dt=1e-3, backend="numpy", error_estimate=False)
    used = ln.Simulator(scene, **kw)
    used.advance(0.002)

    def reused():
        used.reset(state_untouched=True)
        used.advance(0.002)

    cases = {"new Simulator + first advance (2 steps)": lambda: ln.Simulator(scene, **kw).advance(0.002),
             "reset + the same advance": reused,
             "new Simulator alone": lambda: ln.Simulator(scene, **kw)}
    best = {}
    for _ in range(15):
        for name, f in cases.items():
            best[name] = min(best.get(name, np.inf), _cpu_us(f, 50))
    for name, us in best.items():
        print(f"{name:42s} {us:8.1f} us CPU (best of 15 x 50)")
    best = {}
    for _ in range(10):
        for pooled in (False, True):
            NumpyBackend.reusable = pooled
            scene.__dict__.pop("_simulate_pool", None)
            for estimate in (False, True):
                f = lambda: ln.simulate(scene, 0.002, method="rattle", dt=1e-3, backend="numpy", n_out=2,  # noqa
                                        progress=False, error_estimate=estimate)
                f()
                key = f"simulate 2 steps, error_estimate={estimate!s:5}, pooled={pooled!s:5}"
                best[key] = min(best.get(key, np.inf), _cpu_us(f, 30))
    NumpyBackend.reusable = True
    for key, us in sorted(best.items()):
        print(f"{key:55s} {us:8.1f} us CPU (best of 10 x 30)")
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in ("identity", "cost"):
        sys.exit(__doc__)
    sys.exit(identity(sys.argv[2:]) if sys.argv[1] == "identity" else cost())
