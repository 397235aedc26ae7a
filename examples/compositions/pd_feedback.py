#!/usr/bin/env python3
"""Feedback composition: a chain FMU and a PD controller FMU hold the chain's top mass at a target.

    python examples/compositions/pd_feedback.py [--h 0.001] [--t-end 3] [--out build/compositions]

Plant: hanging_chain.json, a free chain of 5 masses (0.5 kg in all), no anchor, gravity -z;
the controller acts on the top mass 1. Controller: F = Kp (x* - x) - Kd v + F_ff with the
feedforward F_ff = M_total g cancelling the weight. The target is 0.1 m straight above the
start, so the chain stays vertical and moves as one rigid body of mass M_total:

    M z'' = Kp (z* - z) - Kd z'      (a damped oscillator: wn = sqrt(Kp/M), zeta = Kd / (2 sqrt(Kp M)))

which is the controller's prediction, in closed form. The co-simulation (zero-order hold over
each communication step h) must follow it with an O(h) error and settle at z*.

Two masters: the short loop in `run` (cosim.py), and with --container fmpy's own container FMU
(fmpy.container_fmu), which wraps the two FMUs and their 9 connections into one FMU that
fmpy.simulate_fmu runs. Workarounds it needed (fmpy 0.3.32), see `build_container`:
  * connections of FMI 2 Reals are written with type "Real", which the container binary
    rejects ("unknown variant `Real`"): rewritten to "Float64" in resources/container.json;
  * the container's first variable (value reference 0) reads back as time: a "time" variable
    (causality independent) is put first.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402
from cosim import Slave, finish, write_container  # noqa: E402

KP, ZETA, LIFT = 50.0, 0.5, 0.1


def predicted_z(t, z0, M):
    """Closed-loop step response of M z'' = Kp (z* - z) - Kd z', from rest at z0, z* = z0 + LIFT."""
    wn = np.sqrt(KP / M)
    wd = wn * np.sqrt(1 - ZETA ** 2)
    return z0 + LIFT - LIFT * np.exp(-ZETA * wn * t) * (np.cos(wd * t) + ZETA * wn / wd * np.sin(wd * t))


def build(out: Path) -> tuple[Path, Path]:
    out.mkdir(parents=True, exist_ok=True)
    chain = build_fmu.build_scene_fmu(HERE / "hanging_chain.json", out / "hanging_chain.fmu", integrator="dop853",
                                      tolerance=1e-10, inputs="1", outputs="1,5", quiet=True)
    pd = build_fmu.build_component_fmu("pd_controller", out / "pd_controller.fmu", quiet=True)
    return chain, pd


def run(chain_fmu, pd_fmu, h: float, t_end: float) -> dict:
    scene = ln.load_scene(HERE / "hanging_chain.json")
    M = float(np.sum(scene.mass))
    g = float(-scene.gravity[2])
    kd = 2 * ZETA * np.sqrt(KP * M)
    x0 = scene.X0[0]
    target = x0 + np.array([0.0, 0.0, LIFT])
    chain = Slave(chain_fmu, "chain")
    pd = Slave(pd_fmu, "pd", start={"Kp": KP, "Kd": kd, "x_target[1]": target[0], "x_target[2]": target[1],
                                   "x_target[3]": target[2], "F_ff[3]": M * g})
    X1, U1, Fc = chain.vector("X", 1), chain.vector("U", 1), chain.vector("F", 1)
    n = int(round(t_end / h))
    ts, top = np.empty(n + 1), np.empty((n + 1, 3))
    start = time.perf_counter()
    t = 0.0
    for k in range(n + 1):
        x, v = chain.get(X1), chain.get(U1)          # no direct feedthrough: states at t
        ts[k], top[k] = t, x
        if k == n:
            break
        pd.set({**dict(zip(pd.vector("x"), x)), **dict(zip(pd.vector("v"), v))})
        chain.set(dict(zip(Fc, pd.get(pd.vector("F")))))   # held over [t, t + h]
        chain.step(t, h)
        pd.step(t, h)
        t = (k + 1) * h
    wall = time.perf_counter() - start
    chain.close()
    pd.close()
    z_pred = predicted_z(ts, x0[2], M)
    return dict(t=ts, top=top, z_pred=z_pred, wall=wall, M=M, kd=kd, target=target,
                max_error=float(np.max(np.abs(top[:, 2] - z_pred))),
                final_error=float(abs(top[-1, 2] - target[2])),
                lateral=float(np.max(np.abs(top[:, :2] - x0[:2]))))


def build_container(chain_fmu, pd_fmu, h: float, out: Path) -> Path:
    """fmpy container FMU of the loop; output z_top (the top mass's z), gains as parameters."""
    import uuid
    from fmpy import read_model_description
    from fmpy.container_fmu import Configuration
    from fmpy.container_fmu.config import Component, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    scene = ln.load_scene(HERE / "hanging_chain.json")
    M, g = float(np.sum(scene.mass)), float(-scene.gravity[2])
    md_c, md_p = read_model_description(str(chain_fmu)), read_model_description(str(pd_fmu))
    vc = {v.name: v for v in md_c.modelVariables}
    vp = {v.name: v for v in md_p.modelVariables}
    chain = Component(name="chain", filename=Path(chain_fmu), modelDescription=md_c)
    ctrl = Component(name="pd", filename=Path(pd_fmu), modelDescription=md_p)
    conns = []
    for i in (1, 2, 3):
        conns += [Connection(startElement=chain, startConnectors=[vc[f"X[1,{i}]"]], endElement=ctrl,
                             endConnectors=[vp[f"x[{i}]"]]),
                  Connection(startElement=chain, startConnectors=[vc[f"U[1,{i}]"]], endElement=ctrl,
                             endConnectors=[vp[f"v[{i}]"]]),
                  Connection(startElement=ctrl, startConnectors=[vp[f"F[{i}]"]], endElement=chain,
                             endConnectors=[vc[f"F[1,{i}]"]])]

    def parameter(name, value):
        v = ModelVariable(name=name, type="Real", causality="parameter", variability="tunable", initial="exact")
        v.start = repr(float(value))
        return v

    time_var = ModelVariable(name="time", type="Real", causality="independent", variability="continuous")
    z_top = ModelVariable(name="z_top", type="Real", causality="output", variability="continuous",
                          initial="calculated", description="z of the chain's top mass (m)")
    params = {"Kp": parameter("Kp", KP), "Kd": parameter("Kd", 2 * ZETA * np.sqrt(KP * M)),
              "x_target[3]": parameter("z_target", scene.X0[0, 2] + LIFT), "F_ff[3]": parameter("F_ff_z", M * g)}
    token = "{" + str(uuid.uuid4()) + "}"
    md = ModelDescription(fmiVersion="2.0", modelName="pd_loop", instantiationToken=token,
                          coSimulation=CoSimulation(modelIdentifier="container_fmu", fixedInternalStepSize=h),
                          modelVariables=[time_var, z_top, *params.values()],
                          defaultExperiment=DefaultExperiment(startTime="0", stopTime="3", stepSize=repr(h)))
    md.guid = token  # FMI 2 name of the instantiation token
    md.outputs = [Unknown(index=2, variable=z_top)]
    md.initialUnknowns = [Unknown(index=2, variable=z_top)]
    mapping = {z_top: [(chain, vc["X[1,3]"])], **{v: [(ctrl, vp[name])] for name, v in params.items()}}
    config = Configuration(parallelDoStep=False, modelDescription=md, components=[chain, ctrl],
                           connections=conns, variableMappings=mapping)
    return write_container(config, out, "pd_loop_container")


def run_container(chain_fmu, pd_fmu, h: float, t_end: float, out: Path) -> dict:
    import fmpy
    fmu = build_container(chain_fmu, pd_fmu, h, out)
    start = time.perf_counter()
    res = fmpy.simulate_fmu(str(fmu), stop_time=t_end, output_interval=h, output=["z_top"])
    wall = time.perf_counter() - start
    scene = ln.load_scene(HERE / "hanging_chain.json")
    z_pred = predicted_z(res["time"], scene.X0[0, 2], float(np.sum(scene.mass)))
    return dict(t=res["time"], z=res["z_top"], z_pred=z_pred, wall=wall,
                max_error=float(np.max(np.abs(res["z_top"] - z_pred))),
                final_error=float(abs(res["z_top"][-1] - scene.X0[0, 2] - LIFT)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--h", type=float, nargs="+", default=[0.004, 0.002, 0.001])
    p.add_argument("--t-end", type=float, default=3.0)
    p.add_argument("--out", default=str(ROOT / "build" / "compositions"))
    p.add_argument("--container", action="store_true", help="also run the loop as an fmpy container FMU")
    a = p.parse_args(argv)
    chain_fmu, pd_fmu = build(Path(a.out))
    runs = [run(chain_fmu, pd_fmu, h, a.t_end) for h in a.h]
    r = runs[-1]
    wn = np.sqrt(KP / r["M"])
    print(f"PD feedback on hanging_chain (M = {r['M']:.3g} kg): Kp = {KP:g} N/m, Kd = {r['kd']:.4g} N s/m, "
          f"wn = {wn:.4g} rad/s, zeta = {ZETA:g}; target z* = z0 + {LIFT:g} m")
    print(f"  predicted overshoot {100 * np.exp(-np.pi * ZETA / np.sqrt(1 - ZETA ** 2)):.2f} %, observed "
          f"{100 * (r['top'][:, 2].max() - r['target'][2]) / LIFT:.2f} % (h = {a.h[-1]:g} s)")
    for h, run_ in zip(a.h, runs):
        print(f"  h = {h:g} s: max |z - z_predicted| = {run_['max_error']:.3e} m, |z(t_end) - z*| = "
              f"{run_['final_error']:.2e} m, max lateral drift {run_['lateral']:.1e} m, wall {run_['wall']:.2f} s")
    if len(runs) > 1:
        orders = [np.log(runs[i]["max_error"] / runs[i + 1]["max_error"]) / np.log(a.h[i] / a.h[i + 1])
                  for i in range(len(runs) - 1)]
        print("  observed order of the co-simulation error: " + ", ".join(f"{o:.2f}" for o in orders))
    if a.container:
        for h in a.h:
            c = run_container(chain_fmu, pd_fmu, h, a.t_end, Path(a.out))
            print(f"  fmpy container FMU, h = {h:g} s: max |z - z_predicted| = {c['max_error']:.3e} m, "
                  f"|z(t_end) - z*| = {c['final_error']:.2e} m, wall {c['wall']:.2f} s")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(8, 4))
        ax.plot(r["t"], r["top"][:, 2], label=f"co-simulation, h = {a.h[-1]:g} s")
        ax.plot(r["t"], r["z_pred"], "--", label="controller's prediction")
        ax.axhline(r["target"][2], color="gray", lw=0.8)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("z of the top mass (m)")
        ax.legend()
        fig.tight_layout()
        png = Path(a.out) / "pd_feedback.png"
        fig.savefig(png, dpi=100)
        print(f"  plot: {png}")
    except ImportError:
        pass
    return 0


if __name__ == "__main__":
    finish(main())
