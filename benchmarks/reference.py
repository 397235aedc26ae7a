"""Reference solutions at error <= 1e-12 m, computed independently of linknet_core and cached.

Method: scipy's DOP853 on the index-1 formulation written from the seed (benchmarks.index1), at two
tolerances, rtol = 1e-13 (check) and rtol = 2.5e-14 (reference, near scipy's floor of 100 eps).
The reference is accepted when the two agree to `AGREE` (1e-12 m) in every mass position; the measured
difference is stored with the reference and reported, and errors below 10x that difference are treated as
unresolved (the reference cannot tell them apart). The constraint residual of the reference is stored too:
the index-1 formulation does not enforce (11), so a small residual is a further independent check.

Scenes with ropes (links that go slack) take the event-driven reference of benchmarks.rope_reference instead,
the same index-1 right-hand side between the events, at the same two tolerances.

Cache: docs/benchmarks/references/<scene>-<digest>-t<t_end>.npz; the digest covers every number in the scene,
so a changed model is recomputed, never silently reused. The one thing a benchmark writes under docs/ without
--merge, on purpose: the cache is tracked, so that the tests and CI compare against references computed once
(0.1 s to 21 minutes each at rtol 2.5e-14: chain_1000's took 1268 s) instead of on every clean clone. A reference
the cache lacks (a new or changed scene) is added there, written whole (a temporary file renamed into place, so
parallel test workers never read half a file), and belongs in the commit that changes the scene.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from .index1 import Index1System
from .output import write_with
from .scene_spec import SceneSpec

CACHE_DIR = Path(__file__).resolve().parent.parent / "docs" / "benchmarks" / "references"
RTOL_CHECK = 1e-13
RTOL_REF = 2.5e-14
AGREE = 1e-12


def solve_index1(spec: SceneSpec, t_end: float, rtol: float, atol: float | None = None):
    """The scene's state at t_end by scipy's DOP853 on the index-1 form (benchmarks.index1: tensions of
    (25)-(26), minimum-norm (31) where A is singular): (X, U, seconds, steps). atol defaults to 1e-3 rtol
    (positions are O(1 m)). The one independent reference of the benchmarks and the tests."""
    sys = Index1System(spec)
    t0 = time.perf_counter()
    # a driven anchor's acceleration jumps at its waypoints: each smooth piece is integrated on its own
    edges = [0.0] + [t for t in sys.breakpoints() if 0.0 < t < t_end] + [t_end]
    y, steps = sys.y0(), 0
    for start, end in zip(edges[:-1], edges[1:]):
        sys.segment_end = end
        sol = solve_ivp(sys.rhs, (start, end), y, method="DOP853", rtol=rtol,
                        atol=rtol * 1e-3 if atol is None else atol)
        if sol.status != 0:
            raise RuntimeError(f"reference for {spec.name} failed: {sol.message}")
        y, steps = sol.y[:, -1], steps + len(sol.t) - 1
    X, U = sys.split(y)
    X, U, _ = sys.drive(t_end, X, U, left=True)  # driven anchors where their motion has them
    return X, U, time.perf_counter() - t0, steps


def _solver(spec: SceneSpec):
    """solve_index1, or for a scene with ropes the event-driven reference (same signature and result)."""
    if not spec.unilateral:
        return solve_index1
    from .rope_reference import solve_ropes
    return lambda s, t_end, rtol: solve_ropes(s, t_end, rtol)[:4]


def reference(spec: SceneSpec, t_end: float, cache: bool = True, log=print) -> dict:
    path = CACHE_DIR / f"{spec.name}-{spec.digest()}-t{t_end:g}.npz"
    if cache and path.exists():
        d = np.load(path)
        return {k: (d[k] if d[k].ndim else d[k].item()) for k in d.files} | {"path": str(path), "cached": True}
    log(f"  reference {spec.name} t_end={t_end}: DOP853 rtol={RTOL_CHECK:g} and {RTOL_REF:g} ...")
    solve = _solver(spec)
    Xc, Uc, sc, _ = solve(spec, t_end, RTOL_CHECK)
    X, U, s, steps = solve(spec, t_end, RTOL_REF)
    diff = float(np.max(np.linalg.norm(X - Xc, axis=1)))
    out = {"X": X, "U": U, "agreement": diff, "verified": diff <= AGREE, "rtol_ref": RTOL_REF,
           "rtol_check": RTOL_CHECK, "seconds": s + sc, "steps": steps,
           "residual": spec.constraint_residual(X),
           "energy_drift": abs(spec.energy(X, U) - spec.energy(spec.X0, spec.U0)) / spec.energy_scale()}
    log(f"    agreement {diff:.3g} m ({'verified' if diff <= AGREE else 'NOT verified'}), "
        f"residual {out['residual']:.3g}, {out['seconds']:.1f} s")
    if cache:
        write_with(path, lambda tmp: np.savez(tmp, **out))
    return out | {"path": str(path), "cached": False}
