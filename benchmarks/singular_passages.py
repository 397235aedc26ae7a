"""What net_10x10 (models/net_10x10.json) does where fixed steps lose it (0.37-0.5 s) and where every tolerance of
dop853 parts (after 1.05 s): along a tight dop853 run (native core, rtol 1e-12) and a looser one (rtol 1e-10), every
OUT s, with the numpy reference (linknet_core.Dynamics) at each sample: the gap between the two runs, the
smallest eigenvalues of A (25) over its largest, the largest tension and its link, the links in compression, the
fastest mass, and (--fixed) where RATTLE at dt 1e-4 parts from the tight run. docs/robust_stepping.md quotes it.

    python3 -m benchmarks.singular_passages [--t-end 1.5] [--out 0.01] [--fixed]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import linknet_core as ln

MODEL = Path(__file__).resolve().parent.parent / "models" / "net_10x10.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=1.5)
    parser.add_argument("--out", type=float, default=0.01)
    parser.add_argument("--fixed", action="store_true", help="also RATTLE at dt 1e-4 against the tight run")
    a = parser.parse_args()
    scene = ln.load_scene(MODEL)
    dyn = ln.Dynamics(scene)
    n_out = int(round(a.t_end / a.out)) + 1
    tight = ln.simulate(scene, a.t_end, method="dop853", rtol=1e-12, n_out=n_out)
    loose = ln.simulate(scene, a.t_end, method="dop853", rtol=1e-10, n_out=n_out)
    fixed = ln.simulate(scene, a.t_end, method="rattle", dt=1e-4, n_out=n_out) if a.fixed else None
    print("t      gap_1e-10  gap_rattle  eig1/max  eig2/max  eig3/max  Tmax     link          compressed  fastest_mass  |U|max")
    for i, t in enumerate(tight.t):
        X, U = tight.X[i], tight.U[i]
        w = np.linalg.eigvalsh(dyn.tension_matrix(X).toarray())
        T = dyn.tensions(X, U)
        gap = float(np.abs(loose.X[i] - X).max())
        gap_fixed = float(np.abs(fixed.X[i] - X).max()) if fixed is not None else float("nan")
        l = int(np.argmax(np.abs(T)))
        speed = np.linalg.norm(U, axis=1)
        k = int(np.argmax(speed))
        print(f"{t:5.2f}  {gap:9.2e}  {gap_fixed:10.2e}  {w[0] / w[-1]:8.2e}  {w[1] / w[-1]:8.2e}  {w[2] / w[-1]:8.2e}  "
              f"{T[l]:7.3g}  {scene.link_label(l).split(' ', 2)[2]:12s}  {int(np.sum(T < 0)):10d}  "
              f"{scene.mass_names[k]:12s}  {speed[k]:6.3g}")
    print("steps: tight", tight.stats["steps"], "rejected", tight.stats["rejected"])


if __name__ == "__main__":
    main()
