#!/usr/bin/env python3
"""linknet demo: build a shipped scene's FMU, simulate it with fmpy under a force input,
print a summary, write a plot of positions and tensions against time and an animation of the run.

    python examples/demo.py [--scene models/chain_10.json] [--t-end 3] [--out build/demo]

The force input is a 2 N upward step at t = 0.5 s plus a 3 Hz, 0.5 N sine, on the z component
of the last mass. fmpy holds it constant over each communication step, as the FMU promises.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402  (the summary's energy bookkeeping and the animation)
from linknet_core import visual  # noqa: E402


def tip_force(t):
    return (2.0 if t >= 0.5 else 0.0) + 0.5 * np.sin(2 * np.pi * 3.0 * t)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=str(ROOT / "models" / "chain_10.json"))
    p.add_argument("--t-end", type=float, default=3.0)
    p.add_argument("--comm-step", type=float, default=0.01, help="communication step (s)")
    p.add_argument("--step", type=float, default=None,
                   help="internal RATTLE step (s); without it the FMU's error-controlled default (dop853, rtol 1e-8)")
    p.add_argument("--out", default=str(ROOT / "build" / "demo"))
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    import fmpy  # imported here so `--help` stays fast

    scene = ln.load_scene(a.scene)
    fmu = build_fmu.build_scene_fmu(a.scene, out / f"{scene.name}.fmu", step=a.step, stop_time=a.t_end,
                                    comm_step=a.comm_step)
    from fmpy.validation import validate_fmu
    problems = validate_fmu(str(fmu))
    print(f"validate_fmu: {'clean' if not problems else problems}")

    tip = int(scene.free_indices[-1])
    n = int(round(a.t_end / a.comm_step))
    times = np.array([k * a.comm_step for k in range(n + 1)])
    fname = f"F[{tip + 1},3]"
    inputs = [f"F[{k + 1},{i + 1}]" for k in scene.free_indices for i in range(3)]  # all given: no fmpy warnings
    signal = np.zeros(len(times), dtype=[("time", float)] + [(nm, float) for nm in inputs])
    signal["time"] = times
    signal[fname] = [tip_force(t) for t in times]
    names = ([f"X[{k + 1},{i + 1}]" for k in range(scene.K) for i in range(3)]
             + [f"U[{k + 1},{i + 1}]" for k in range(scene.K) for i in range(3)]
             + [f"T[{l + 1}]" for l in range(scene.L)] + ["error_estimate"])
    t0 = time.perf_counter()
    res = fmpy.simulate_fmu(str(fmu), stop_time=a.t_end, output_interval=a.comm_step, input=signal, output=names)
    wall = time.perf_counter() - t0

    t = res["time"]
    X = np.stack([res[nm] for nm in names[:3 * scene.K]], axis=1).reshape(-1, scene.K, 3)
    U = np.stack([res[nm] for nm in names[3 * scene.K:6 * scene.K]], axis=1).reshape(-1, scene.K, 3)
    T = np.stack([res[nm] for nm in names[6 * scene.K:-1]], axis=1) if scene.L else np.zeros((len(t), 0))
    error_estimate = res["error_estimate"]

    # Energy bookkeeping: with F held constant over each step, the input's work over a step is
    # exactly F . (X(t+h) - X(t)); E - W is then a conserved quantity of the exact motion.
    dyn = ln.Dynamics(scene)
    energy = np.array([dyn.energy(X[k], U[k]) for k in range(len(t))])
    F_held = np.array([tip_force(tk) for tk in t[:-1]])
    work = np.concatenate([[0.0], np.cumsum(F_held * np.diff(X[:, tip, 2]))])
    balance = energy - work
    scale = max(abs(energy[0]), float(np.max(np.abs(energy - energy[0]))), 1e-300)
    drift = float(balance[-1] - balance[0]) / scale
    d = X[:, scene.k2] - X[:, scene.k1]
    residual = float(np.max(np.abs(np.linalg.norm(d, axis=2) / scene.length - 1.0))) if scene.L else 0.0

    print(f"scene {scene.name}: {scene.K} masses, {scene.L} links; FMU {fmu}")
    print(f"  input: {fname} = 2 N step at 0.5 s + 0.5 N sine at 3 Hz, held over each communication step")
    inner = (f"internal RATTLE steps = {int(round(a.t_end / a.step))} of {a.step:g} s" if a.step else
             "integrator dop853 at rtol 1e-8 (the FMU's error-controlled default)")
    print(f"  communication steps = {len(t) - 1} of {a.comm_step:g} s, {inner}, wall time = {wall:.2f} s "
          "(fmpy, incl. FMU load)")
    goal = ln.Simulator(scene, method=None if a.step is None else "rattle", dt=a.step, error_estimate=False).error_goal
    over = error_estimate > goal
    verdict = (f"within the goal {goal:.3g} m" if not over.any() else
               f"beyond the goal {goal:.3g} m from t = {t[np.argmax(over)]:g} s: the forced chain's motion grows "
               "chaotic there (the error of any tolerance grows about x10 per 0.1 s, docs/accuracy.md)")
    print(f"  estimated position error (the FMU's error_estimate output) = {float(error_estimate.max()):.3e} m at "
          f"most, {verdict}")
    print(f"  final energy drift (E - input work, relative) = {drift:.3e}")
    print(f"  max constraint residual (relative, |X_k2 - X_k1| / R_l - 1) = {residual:.3e}")
    if scene.L:
        l_max = int(np.unravel_index(np.argmax(T), T.shape)[1])
        print(f"  max tension = {float(T.max()):.6g} N (link {l_max + 1}), min tension = {float(T.min()):.6g} N")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    shown = sorted(set(np.linspace(0, len(scene.free_indices) - 1, min(4, len(scene.free_indices))).astype(int)))
    for j in shown:
        k = int(scene.free_indices[j])
        ax1.plot(t, X[:, k, 0], label=f"x, mass {k + 1}")
        ax1.plot(t, X[:, k, 2], "--", label=f"z, mass {k + 1}")
    ax1.set_ylabel("position (m)")
    ax1.legend(ncol=2, fontsize=8)
    ax1.set_title(f"{scene.name} FMU driven by fmpy: force input on mass {tip + 1} (z)")
    for l in sorted(set(np.linspace(0, scene.L - 1, min(5, scene.L)).astype(int))):
        ax2.plot(t, T[:, l], label=f"T[{l + 1}]")
    ax2.set_ylabel("tension (N)")
    ax2.set_xlabel("time (s)")
    ax2.legend(ncol=3, fontsize=8)
    fig.tight_layout()
    png = out / f"{scene.name}_demo.png"
    fig.savefig(png, dpi=110)
    print(f"  plot: {png}")

    motion = visual.Motion.from_arrays(scene, t, X, T, title=f"{scene.name} FMU, force input on mass {tip + 1} (z)")
    print(f"  animation: {visual.write_animation(motion, out / f'{scene.name}_demo.gif').line()}")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # pythonfmu 0.7.0 can corrupt the heap while finalizing Python at process exit (exit 134)
    # after all work is done; leave without running library destructors (docs/fmu.md).
    os._exit(code)
