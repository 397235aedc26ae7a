#!/usr/bin/env python3
"""Coupling composition: two network FMUs joined by a spring-damper FMU, against the monolithic scene.

    python examples/compositions/coupling.py [--h 0.02 0.01 0.005 0.0025] [--t-end 1] [--ssp]

Network A is a double pendulum (net_a.json), network B a pendulum pivoted 1 m away (net_b.json);
a spring-damper (k = 20 N/m, d0 = 1 m, c = 0.5 N s/m) joins A's tip (mass 3) to B's bob (mass 2).
The monolithic reference is one linknet scene holding both networks and that spring (the
core's "springs" force element), integrated by linknet_core with the same integrator.

Two masters drive the three FMUs:
  * `master` (cosim.py): at each communication point read the coupled masses' positions and
    velocities (no direct feedthrough), evaluate the spring FMU, set its forces on both
    networks, held over [t, t + h] (explicit zero-order-hold coupling);
  * `--ssp`: fmpy's own SSP simulator (fmpy.ssp.simulation.simulate_ssp) on an .ssp archive
    written here. It is a Jacobi master that reads outputs only after each doStep, so the
    spring's output reaches the networks one step later, and its connectors start at 0.
Both converge to the monolithic result as h shrinks; the observed order is printed.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402
from cosim import Slave, finish, observed_orders  # noqa: E402

SPRING = dict(stiffness=20.0, rest_length=1.0, damping=0.5)
A_TIP, B_BOB = 3, 2          # 1-based masses joined by the spring
RTOL = 1e-11                  # inner integrator (dop853) tolerance, far below the coupling error
SAMPLE = 0.02                 # errors compared at multiples of this time


def monolithic_scene() -> ln.Scene:
    """Both networks and the spring-damper in one scene."""
    a = json.loads((HERE / "net_a.json").read_text())
    b = json.loads((HERE / "net_b.json").read_text())
    masses = [dict(m, name="A." + m["name"]) for m in a["masses"]] + \
             [dict(m, name="B." + m["name"]) for m in b["masses"]]
    n_a = len(a["masses"])
    links = a["links"] + [dict(l, a=l["a"] + n_a, b=l["b"] + n_a) for l in b["links"]]
    return ln.Scene.from_dict({"name": "coupled_monolithic", "gravity": a["gravity"], "masses": masses,
                               "links": links, "springs": [dict(a=A_TIP, b=n_a + B_BOB, **SPRING)]})


def monolithic_reference(t_end: float) -> dict:
    res = ln.simulate(monolithic_scene(), t_end, method="dop853", rtol=RTOL, output_dt=SAMPLE)
    n_a = 3
    return dict(t=res.t, xa=res.X[:, A_TIP - 1], xb=res.X[:, n_a + B_BOB - 1])


def build(out: Path) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    opts = dict(integrator="dop853", tolerance=RTOL, quiet=True)
    return dict(
        a=build_fmu.build_scene_fmu(HERE / "net_a.json", out / "net_a.fmu", inputs=str(A_TIP), **opts),
        b=build_fmu.build_scene_fmu(HERE / "net_b.json", out / "net_b.fmu", inputs=str(B_BOB), **opts),
        spring=build_fmu.build_component_fmu("spring_damper", out / "spring_damper.fmu", quiet=True))


def master(fmus: dict, h: float, t_end: float) -> dict:
    """Explicit coupling with the cosim.Slave helper; returns the coupled masses' positions."""
    a, b = Slave(fmus["a"], "a"), Slave(fmus["b"], "b")
    spring = Slave(fmus["spring"], "spring", start=SPRING)
    n = int(round(t_end / h))
    every = int(round(SAMPLE / h))
    xa_rows, xb_rows = [], []
    start = time.perf_counter()
    t = 0.0
    for k in range(n + 1):
        xa, va = a.get(a.vector("X", A_TIP)), a.get(a.vector("U", A_TIP))
        xb, vb = b.get(b.vector("X", B_BOB)), b.get(b.vector("U", B_BOB))
        if k % every == 0:
            xa_rows.append(xa)
            xb_rows.append(xb)
        if k == n:
            break
        spring.set({**dict(zip(spring.vector("xa"), xa)), **dict(zip(spring.vector("va"), va)),
                    **dict(zip(spring.vector("xb"), xb)), **dict(zip(spring.vector("vb"), vb))})
        a.set(dict(zip(a.vector("F", A_TIP), spring.get(spring.vector("Fa")))))
        b.set(dict(zip(b.vector("F", B_BOB), spring.get(spring.vector("Fb")))))
        for s in (a, b, spring):
            s.step(t, h)
        t = (k + 1) * h
    wall = time.perf_counter() - start
    for s in (a, b, spring):
        s.close()
    return dict(xa=np.array(xa_rows), xb=np.array(xb_rows), wall=wall)


def write_ssp(fmus: dict, path: Path) -> Path:
    """An SSP 1.0 archive of the three FMUs and their 18 connections."""
    conns = []
    for i in (1, 2, 3):
        conns += [("a", f"X[{A_TIP},{i}]", "spring", f"xa[{i}]"), ("a", f"U[{A_TIP},{i}]", "spring", f"va[{i}]"),
                  ("b", f"X[{B_BOB},{i}]", "spring", f"xb[{i}]"), ("b", f"U[{B_BOB},{i}]", "spring", f"vb[{i}]"),
                  ("spring", f"Fa[{i}]", "a", f"F[{A_TIP},{i}]"), ("spring", f"Fb[{i}]", "b", f"F[{B_BOB},{i}]")]
    connectors = {"a": [], "b": [], "spring": []}
    for s_el, s_con, e_el, e_con in conns:
        connectors[s_el].append((s_con, "output"))
        connectors[e_el].append((e_con, "input"))
    elements = []
    for name in ("a", "b", "spring"):
        cons = "".join(f'<ssd:Connector name="{c}" kind="{k}"><ssc:Real/></ssd:Connector>' for c, k in connectors[name])
        elements.append(f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" '
                        f'source="resources/{name}.fmu"><ssd:Connectors>{cons}</ssd:Connectors></ssd:Component>')
    connections = "".join(f'<ssd:Connection startElement="{a}" startConnector="{b}" endElement="{c}" endConnector="{d}"/>'
                          for a, b, c, d in conns)
    ssd = ('<?xml version="1.0" encoding="UTF-8"?>'
           '<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
           'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="coupled">'
           f'<ssd:System name="coupled"><ssd:Elements>{"".join(elements)}</ssd:Elements>'
           f'<ssd:Connections>{connections}</ssd:Connections></ssd:System></ssd:SystemStructureDescription>')
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        for name in ("a", "b", "spring"):
            z.write(fmus[name], f"resources/{name}.fmu")
    return path


def ssp_master(fmus: dict, h: float, t_end: float, out: Path) -> dict:
    """fmpy's SSP simulator. It records each row *after* the step that starts at the row's
    time, so row n holds the outputs at t_n + h: shift by one to align with t = 0, h, 2h ..."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet
    ssp = write_ssp(fmus, out / "coupled.ssp")
    params = ParameterSet(name="spring")
    params.parameters = [Parameter(name=f"spring.{k}", type="Real", value=v) for k, v in SPRING.items()]
    start = time.perf_counter()
    # stop slightly past t_end: fmpy's loop runs `while time < stop_time` with time += h
    res = simulate_ssp(str(ssp), stop_time=t_end + 0.5 * h, step_size=h, parameter_set=params)
    wall = time.perf_counter() - start
    every = int(round(SAMPLE / h))
    xa_after = np.stack([res[f"a.X[{A_TIP},{i}]"] for i in (1, 2, 3)], 1)
    xb_after = np.stack([res[f"b.X[{B_BOB},{i}]"] for i in (1, 2, 3)], 1)
    scene_a = ln.load_scene(HERE / "net_a.json")
    scene_b = ln.load_scene(HERE / "net_b.json")
    xa = np.vstack([scene_a.X0[A_TIP - 1], xa_after])[::every]
    xb = np.vstack([scene_b.X0[B_BOB - 1], xb_after])[::every]
    n_samples = int(round(t_end / SAMPLE)) + 1
    return dict(xa=xa[:n_samples], xb=xb[:n_samples], wall=wall)


def errors(run: dict, ref: dict) -> float:
    return float(max(np.max(np.linalg.norm(run["xa"] - ref["xa"], axis=1)),
                     np.max(np.linalg.norm(run["xb"] - ref["xb"], axis=1))))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--h", type=float, nargs="+", default=[0.02, 0.01, 0.005, 0.0025])
    p.add_argument("--t-end", type=float, default=1.0)
    p.add_argument("--ssp", action="store_true", help="also run fmpy's SSP simulator")
    p.add_argument("--out", default=str(ROOT / "build" / "compositions"))
    a = p.parse_args(argv)
    out = Path(a.out)
    fmus = build(out)
    ref = monolithic_reference(a.t_end)
    masters = [("master loop (cosim.py)", lambda h: master(fmus, h, a.t_end))]
    if a.ssp:
        masters.append(("fmpy SSP simulator", lambda h: ssp_master(fmus, h, a.t_end, out)))
    print(f"coupling net_a (mass {A_TIP}) -- spring-damper {SPRING} -- net_b (mass {B_BOB}), t_end = {a.t_end:g} s; "
          f"error = max over t of |x_cosim - x_monolithic| at the two coupled masses")
    for label, run in masters:
        errs = []
        for h in a.h:
            r = run(h)
            errs.append(errors(r, ref))
            print(f"  {label}: h = {h:g} s  error = {errs[-1]:.3e} m  (wall {r['wall']:.2f} s)")
        if len(errs) > 1:
            print(f"  {label}: observed orders " + ", ".join(f"{o:.2f}" for o in observed_orders(a.h, errs)))
    return 0


if __name__ == "__main__":
    finish(main())
