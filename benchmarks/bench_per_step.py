"""Integration cost per step, small scenes to large: CPU time of one long ``Simulator.advance`` divided by its steps.

    python benchmarks/bench_per_step.py [--rounds 5] [--only pendulum,chain_100]
    (any tree of the package: PYTHONPATH=TREE, working directory TREE; uses only the public API and the tree's
    models/, so the numba-era tree at 71c3c90 runs it unchanged)

One warm-up call of 1 ms first (a JIT-compiled core loads its cache there), then one advance to the case's end
time; the figure is the best of ``--rounds`` fresh Simulators (CPU time of this process, garbage collector off
during the advance). Long advances make the per-call cost negligible: what is left is the step loop itself.
Measures; asserts nothing.
"""
from __future__ import annotations

import argparse
import gc
import os
import time

import linknet_core as ln

try:
    from linknet_core.scene import builders
except ImportError:  # the numba-era layout
    from linknet_core import builders

CASES = [  # scene, method, settings, end time of the long advance
    ("pendulum", "rattle", dict(dt=1e-4), 20.0),
    ("pendulum", "yoshida6", dict(dt=1e-3), 20.0),
    ("pendulum", "dop853", dict(rtol=1e-12, atol=1e-12), 20.0),
    ("pendulum", "dopri5", dict(rtol=1e-10, atol=1e-10), 20.0),
    ("double_pendulum", "rattle", dict(dt=1e-4), 5.0),
    ("double_pendulum", "dop853", dict(rtol=1e-12, atol=1e-12), 5.0),
    ("chain_10", "rattle", dict(dt=1e-4), 2.0),
    ("chain_10", "dop853", dict(rtol=1e-10, atol=1e-10), 2.0),
    ("chain_100", "rattle", dict(dt=1e-4), 0.2),
    ("chain_100", "dop853", dict(rtol=1e-10, atol=1e-10), 0.5),
    ("chain_1000", "rattle", dict(dt=1e-4), 0.01),
    ("net_60x60", "rattle", dict(dt=1e-3), 0.01),
]


def scene_of(name: str):
    if name == "chain_1000":
        return builders.chain(1000, shape="horizontal")
    if name == "net_60x60":
        return builders.net(60, 60)
    return ln.load_scene(os.path.join(os.getcwd(), "models", f"{name}.json"))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--only", default=None, help="comma-separated scene names")
    args = p.parse_args(argv)
    only = args.only.split(",") if args.only else None
    for name, method, settings, t_end in CASES:
        if only and name not in only:
            continue
        scene = scene_of(name)
        best, steps = None, 0
        for _ in range(args.rounds):
            sim = ln.Simulator(scene, method=method, error_estimate=False, **settings)
            sim.advance(1e-3)
            before = sim.integrator.stats.steps
            gc.disable()
            cpu = time.process_time()
            sim.advance(t_end)
            cpu = time.process_time() - cpu
            gc.enable()
            steps = sim.integrator.stats.steps - before
            best = cpu / steps if best is None else min(best, cpu / steps)
        setting = " ".join(f"{k} {v:g}" for k, v in settings.items())
        print(f"{name:16s} {method:9s} {setting:22s} {1e9 * best:12.1f} ns/step  ({steps} steps)", flush=True)


if __name__ == "__main__":
    main()
