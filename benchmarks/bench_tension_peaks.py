"""What the located tension peaks cost: the integration alone, in source trees with and without them.

Every native run locates each link's tension peak between its outputs (linknet_core/native/src/tension_peaks.c): O(L)
work per accepted step, and for RATTLE and its compositions one solve per step (and one per advance) on the
factorisation the velocity projection leaves, since their steps evaluate no tensions otherwise. The cost is the CPU
time (time.process_time) of ``Simulator.advance`` over the run (``error_estimate=False``: the integration alone), in
one advance or in advances of ``--interval`` (an FMU's communication steps), best of ``--repeat`` in each of
``--rounds`` rounds that visit the trees in turn (so that the load of a shared machine falls on each alike), each tree
in its own process with its own build of the native core (``python3 setup.py build_ext --inplace`` in each first).

    python3 -m benchmarks.bench_tension_peaks --trees /tmp/before /tmp/fields_only . [--rounds 4] [--repeat 8]

compares, say, the commit before the peaks, that commit with only the new ln_data fields (unused: what the layout of
the data alone does to the times), and this tree. Measures only; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CASES = [  # scene, t_end, method, settings
    ("chain_100", 1.0, "dop853", {}),
    ("chain_100", 1.0, "rattle", {"dt": 1e-3}),
    ("chain_100", 1.0, "yoshida4", {"dt": 1e-3}),
    ("net_10x10", 1.0, "dop853", {}),
    ("net_10x10", 1.0, "rattle", {"dt": 1e-3}),
    ("net_10x10", 1.0, "yoshida4", {"dt": 1e-3}),
]

# run in each tree's own interpreter: the best CPU time (ms) of `repeat` runs of one case
CHILD = """
import json, sys, time
import linknet_core as ln
scene, t_end, method, settings, interval, repeat = json.loads(sys.argv[1])
scene = ln.load_scene(f"models/{scene}.json")
times = [t_end] if interval is None else [min(t_end, (i + 1) * interval) for i in range(round(t_end / interval))]
best = float("inf")
for _ in range(repeat):
    sim = ln.Simulator(scene, method=method, error_estimate=False, **settings)
    start = time.process_time()
    for t in times:
        sim.advance(t)
    best = min(best, time.process_time() - start)
print(1e3 * best)
"""


def child_time(tree: Path, case: tuple, interval, repeat: int) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps([*case, interval, repeat])], cwd=tree, env=env,
                         capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", nargs="+", required=True, help="source trees, the first the baseline")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--repeat", type=int, default=8)
    parser.add_argument("--interval", type=float, default=None, help="advance in steps of this (s); default: one")
    parser.add_argument("--json", help="write the table here too")
    args = parser.parse_args(argv)
    trees = [Path(t).resolve() for t in args.trees]
    rows = []
    print("| scene | method | " + " | ".join(t.name for t in trees) + " |")
    for case in CASES:
        best = [float("inf")] * len(trees)
        for _ in range(args.rounds):
            for j, tree in enumerate(trees):
                best[j] = min(best[j], child_time(tree, case, args.interval, args.repeat))
        cells = [f"{best[0]:.3g} ms"] + [f"{b:.3g} ms ({100 * (b / best[0] - 1):+.1f} %)" for b in best[1:]]
        print(f"| {case[0]} | {case[2]} {case[3] or ''} | " + " | ".join(cells) + " |", flush=True)
        rows.append({"scene": case[0], "method": case[2], "settings": case[3], "interval": args.interval,
                     "cpu_ms": dict(zip(map(str, trees), best))})
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
