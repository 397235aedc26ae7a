"""Issue 2's performance figure: a chain of N links falling from horizontal, RATTLE at fixed dt.

python -m benchmarks.bench_kernel_rattle [--links 1000] [--t-end 1.0] [--dt 1e-4]
Reports wall time, time per step and time per step per link (measures; asserts nothing). The CPU time of
this process is reported beside the wall time: on a shared machine other processes inflate the latter.
"""
from __future__ import annotations

import argparse
import time

import linknet_core as ln
from linknet_core.scene import builders


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--links", type=int, default=1000)
    p.add_argument("--t-end", type=float, default=1.0)
    p.add_argument("--dt", type=float, default=1e-4)
    p.add_argument("--method", default="rattle")
    args = p.parse_args(argv)
    scene = builders.chain(args.links, shape="horizontal")
    ln.simulate(builders.chain(3), t_end=1e-3, dt=1e-4, n_out=2)  # compile the kernels outside the timing
    start = time.perf_counter()
    cpu_start = time.process_time()
    try:
        res = ln.simulate(scene, t_end=args.t_end, method=args.method, dt=args.dt, n_out=101, progress=False,
                          error_estimate=False)
    except ln.SolverError as exc:
        # a whipping chain's tip can move more than a link length per step: report where it stopped
        sim = ln.Simulator(scene, method=args.method, dt=args.dt, error_estimate=False)
        t = 0.0
        start = time.perf_counter()
        try:
            while t < args.t_end:
                sim.advance(min(t + 0.01, args.t_end))
                t = sim.state.t
        except ln.SolverError:
            pass
        print(f"chain_{args.links} {args.method} dt={args.dt:g}: stopped at t = {sim.state.t:.2f} s "
              f"({time.perf_counter() - start:.2f} s wall): {exc}")
        return 1
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    steps = res.stats["steps"]
    print(res.summary())
    print(f"peak tip speed {float(abs(res.U[:, -1]).max()):.3g} m/s (link length {scene.length[0]:g} m)")
    print(f"chain_{args.links} {args.method} dt={args.dt:g} t_end={args.t_end:g}: wall {wall:.3f} s, "
          f"{steps} steps, {1e6 * wall / steps:.1f} us/step, {1e9 * wall / steps / args.links:.1f} ns/step/link; "
          f"CPU {cpu:.3f} s, {1e9 * cpu / steps / args.links:.1f} ns/step/link")


if __name__ == "__main__":
    main()
