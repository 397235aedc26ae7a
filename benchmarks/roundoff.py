"""Round-off of the fixed-step methods as the step shrinks, and where the scene sits.

RATTLE and its compositions add a small increment h U to positions of size |X| every step. Each sum is rounded to
ulp(|X|); where that rounding reaches the velocity (U_half = (X_new - X) / h) it becomes a velocity error of
ulp(|X|) / h per step, a random walk whose position error grows like ulp(|X|) N^1.5 over N steps, so that it
grows as dt shrinks and with the distance of the scene from the origin.

Scenes (each against a reference independent of linknet_core):
  pendulum        the 1 m pendulum released horizontally (builders.pendulum), pivot at the origin: the
                  analytic solution (Jacobi elliptic functions);
  pendulum_1km    the same pendulum with every position shifted 1 km along x: the same analytic solution, shifted;
  mixed_links     a 1e3 m link from an anchor at the origin and a 1e-4 m link hanging from its end, both swinging
                  (the small one fast): scipy's DOP853 on the index-1 form (benchmarks.reference.solve_index1) at
                  two tolerances, whose difference is printed as the reference's own error.

The error is the largest distance of a mass from its reference position at t_end, in metres.

    python -m benchmarks.roundoff                      # the pendulums, native and numpy, rattle and yoshida4, t_end 0.1 s
    python -m benchmarks.roundoff --scene mixed_links --t-end 0.02 --backend native
    python -m benchmarks.roundoff --t-end 1 --backend native
"""
from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np
from scipy.special import ellipj, ellipk

import linknet_core as ln
from linknet_core.scene import builders

G = 9.81
SHIFT_1KM = np.array([1000.0, 0.0, 0.0])


def pendulum(offset=(0.0, 0.0, 0.0)) -> ln.Scene:
    """The 1 m, 1 kg pendulum released at rest 90 deg from the vertical, every position moved by ``offset``."""
    scene = builders.pendulum(length=1.0, angle_deg=90.0, gravity=(0.0, 0.0, -G))
    return scene.with_state(X0=scene.X0 + np.asarray(offset, np.float64), U0=scene.U0)


def pendulum_exact(t: float, offset=(0.0, 0.0, 0.0), length=1.0) -> np.ndarray:
    """The bob of ``pendulum(offset)`` at t: with k = sin(theta0 / 2), sin(theta / 2) = k sn(K - w t | k^2) and
    cos(theta / 2) = dn(K - w t | k^2), w = sqrt(g / L); bob = pivot + L (sin theta, 0, -cos theta)."""
    m = 0.5  # k^2 = sin^2(45 deg)
    k = math.sqrt(m)
    sn, _, dn, _ = ellipj(ellipk(m) - math.sqrt(G / length) * t, m)
    bob = np.array([length * 2.0 * k * sn * dn, 0.0, -length * (1.0 - 2.0 * m * sn * sn)])
    return bob + np.asarray(offset, np.float64)


def mixed_links() -> ln.Scene:
    """An anchor at the origin, a 1e3 m link to a 1 kg mass released 30 deg below the horizontal, and from it a
    1e-4 m link to a 1e-3 kg mass pointing sideways with a speed across the link, so that both links move."""
    big, small = 1e3, 1e-4
    a = math.radians(30.0)
    tip = np.array([big * math.cos(a), 0.0, -big * math.sin(a)])
    d = {"name": "mixed_links", "description": "a 1e3 m and a 1e-4 m link", "gravity": [0.0, 0.0, -G],
         "masses": [{"name": "anchor", "position": [0.0, 0.0, 0.0], "fixed": True},
                    {"name": "heavy", "position": tip.tolist(), "mass": 1.0},
                    {"name": "light", "position": (tip + [0.0, small, 0.0]).tolist(), "mass": 1e-3,
                     "velocity": [0.0, 0.0, 0.02]}],
         "links": [{"a": 1, "b": 2, "length": big}, {"a": 2, "b": 3, "length": small}]}
    return ln.Scene.from_dict(d)


def mixed_reference(t_end: float):
    """(positions at t_end, the two tolerances' difference) from scipy's DOP853 on the index-1 form."""
    from benchmarks.reference import solve_index1
    from benchmarks.scene_spec import SceneSpec
    spec = SceneSpec.from_core(mixed_links())
    X_ref = solve_index1(spec, t_end, rtol=2.5e-14, atol=1e-17)[0]
    X_check = solve_index1(spec, t_end, rtol=1e-13, atol=1e-16)[0]
    return X_ref, float(np.linalg.norm(X_ref - X_check, axis=1).max())


def error(scene, X_ref, t_end, method, dt, backend) -> float:
    res = ln.simulate(scene, t_end=t_end, method=method, dt=dt, n_out=2, backend=backend)
    return float(np.linalg.norm(res.X[-1] - X_ref, axis=1).max())


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--t-end", type=float, default=0.1)
    parser.add_argument("--backend", action="append", choices=["native", "numpy"])
    parser.add_argument("--method", action="append")
    parser.add_argument("--dt", type=float, action="append")
    parser.add_argument("--scene", action="append", choices=["pendulum", "pendulum_1km", "mixed_links"])
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")  # the runs' own error estimates: this table measures the true error
    t_end = args.t_end
    backends = args.backend or ["native", "numpy"]
    methods = args.method or ["rattle", "yoshida4"]
    dts = args.dt or [1e-4, 1e-5, 1e-6]
    scenes = {"pendulum": (pendulum(), np.array([[0.0, 0.0, 0.0], pendulum_exact(t_end)])),
              "pendulum_1km": (pendulum(SHIFT_1KM), np.array([SHIFT_1KM, pendulum_exact(t_end, SHIFT_1KM)]))}
    wanted = args.scene or ["pendulum", "pendulum_1km"]  # mixed_links on request: its reference takes minutes
    if "mixed_links" in wanted:
        X_ref, agree = mixed_reference(t_end)
        print(f"mixed_links reference: two tolerances agree to {agree:.2g} m")
        scenes["mixed_links"] = (mixed_links(), X_ref)
    print(f"t_end = {t_end} s; error = largest distance from the reference at t_end, m")
    print(f"{'scene':<14}{'backend':<8}{'method':<10}" + "".join(f"{'dt ' + format(dt, 'g'):>12}" for dt in dts)
          + f"{'seconds':>10}")
    for name in wanted:
        scene, X_ref = scenes[name]
        for backend in backends:
            for method in methods:
                start = time.perf_counter()
                errors = [error(scene, X_ref, t_end, method, dt, backend) for dt in dts]
                print(f"{name:<14}{backend:<8}{method:<10}" + "".join(f"{e:12.2e}" for e in errors)
                      + f"{time.perf_counter() - start:10.1f}", flush=True)


if __name__ == "__main__":
    main()
