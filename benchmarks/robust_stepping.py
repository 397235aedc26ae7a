"""Scene x method table of robust stepping: every shipped scene (models/*.json, plus the two redundant
scenes with mechanisms and a chain with masses 1e3 .. 1e-3) with every method at its default settings (dt = 1e-3,
rtol = 1e-8) on the native core to t = 2 s (the DefaultExperiment stopTime build_fmu.py writes), and for the
redundant scenes the largest position error at t = 0.3 s against the independent reference of
benchmarks.reference.solve_index1.

    python3 benchmarks/robust_stepping.py            # this checkout
    PYTHONPATH=<other checkout> python3 benchmarks/robust_stepping.py --models <this checkout>/models
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent
METHODS = ("rattle", "yoshida4", "suzuki4", "yoshida6", "yoshida8", "dopri5", "dop853")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", default=str(HERE / "models"))
    p.add_argument("--t-end", type=float, default=2.0)
    a = p.parse_args()
    import linknet_core as ln
    sys.path.insert(0, str(HERE))
    from benchmarks.reference import solve_index1
    from benchmarks.scene_spec import SceneSpec

    from linknet_core.scene.description import load_scene

    scenes = {}
    for f in sorted(Path(a.models).glob("*.json")):
        try:
            scenes[f.stem] = load_scene(f)
        except Exception as e:  # noqa: BLE001 - an older checkout may not read a newer scene format
            print(f"  {f.stem}: not loaded ({str(e)[:120]})", file=sys.stderr)
    masses = np.geomspace(1e3, 1e-3, 11)
    scenes["chain_ratio_1e6"] = ln.Scene.from_dict({
        "name": "chain_ratio_1e6", "masses": [{"name": "m0", "position": [0, 0, 0], "fixed": True}]
        + [{"name": f"m{i}", "position": [0.1 * i, 0, 0], "mass": float(masses[i])} for i in range(1, 11)],
        "links": [{"a": i + 1, "b": i + 2} for i in range(10)]})
    print(f"{'scene':22s} " + " ".join(f"{m:>10s}" for m in METHODS))
    for name, scene in scenes.items():
        cells = []
        ref = None
        if name in ("triangulated_net", "braced_tower"):
            ref = solve_index1(SceneSpec.from_core(scene), 0.3, rtol=1e-12, atol=1e-12)[0]
        for method in METHODS:
            settings = dict(rtol=1e-8) if method.startswith("dop") else dict(dt=1e-3)
            try:
                sim = ln.Simulator(scene, method=method, backend="native", **settings)
                if ref is not None:
                    sim.advance(0.3)
                    err = float(np.abs(sim.state.X - ref).max())
                sim.advance(a.t_end)
                cells.append(f"{err:10.1e}" if ref is not None else f"{'ok':>10s}")
            except Exception as e:  # noqa: BLE001 - the table records any failure
                cells.append(f"{'FAIL':>10s}")
                print(f"  {name} {method}: {e}", file=sys.stderr)
        print(f"{name:22s} " + " ".join(cells), flush=True)


if __name__ == "__main__":
    main()
