#!/usr/bin/env python3
"""Motion coupling: a cart FMU carries a hanging chain FMU through a driven anchor; against a monolithic reference.

    python examples/compositions/cart_chain.py [--h 0.008 0.004 0.002 0.001] [--t-end 2] [--kind native|python|both]
                                               [--stability] [--ssp] [--container] [--library]

The chain (cart_chain.json: 5 masses of 0.2 kg on 0.2 m links) hangs from the hook, mass 1, a driven anchor with
motion "input". It starts straight, 0.7 rad from the vertical, at rest; the cart (fmu_src/cart.py, mass m_c)
starts at rest under the hook. Each communication step [t, t + h] the master

  1. reads the cart's x and v (states: no direct feedthrough) and sets them as the hook's P[1,1], V[1,1];
  2. reads the chain's Freact[1,1] (the force the chain exerts on the hook, along the rail; it depends directly
     on P, V and on A, still the last step's) and sets it as the cart's force F;
  3. reads the cart's a (= F/m_c, direct feedthrough) and sets it as the hook's A[1,1];
  4. steps both FMUs over [t, t + h].

The cart integrates its held force exactly, so its motion over the step *is* the quadratic x + v tau + a tau^2/2
that the chain holds for the hook: the hook follows the cart exactly, its velocity never jumps between steps (no
impulse). The coupling is explicit: the force reaches the cart with a zero-order hold and a one-step lag (in step 2
Freact is computed with the previous step's hook acceleration), so the error is first order in h. Whether this is
called Jacobi or Gauss-Seidel makes no difference here: the cart's motion over the step is known at its start, so
the chain gets it exactly either way ("cart first").

The lag is an added-mass loop. With the chain's state held, Freact = F0(q) - m_eff(q) A, where m_eff is the
chain's added mass along the rail (cart_chain_reference.CartChain.added_mass; for a straight chain at angle
theta from the vertical, m_chain sin^2(theta)). So a_n = (F0 - m_eff a_(n-1))/m_c: the start-up error of a
is multiplied by -m_eff/m_c each step. The coupling is stable while m_c > m_eff along the motion, and blows up
below: here m_eff is largest at the release, m_chain sin^2(0.7) = 0.415 m_chain. --stability measures it.

The monolithic reference (cart_chain_reference.py) is written independently of linknet: generalized coordinates
(x, theta_1..theta_5), Lagrange's equations, scipy DOP853 at rtol 1e-12.

Other masters:
  * --library: the same loop on linknet_core.Simulator(anchors=) and the cart's closed form, no FMU (a check of
    the FMUs against the library they wrap);
  * --ssp: fmpy's SSP simulator (fmpy.ssp.simulation.simulate_ssp) on an .ssp archive written here. It is a
    Jacobi master that reads each FMU's outputs right after its own doStep: the cart's a read there is the
    acceleration of the step just taken, so the hook's A lags the cart's by one step, the hook's motion over
    a step is not the cart's, and its velocity jumps (by (a_n - a_(n-1)) h) at every communication point,
    which the chain takes as a small inelastic impulse; Freact is read before the new P, V are set (for the
    hook still at the old P). Its connectors start at 0 (the cart's first force is 0). First order still,
    with ~5x the error. `master(..., scheme="jacobi")` is that scheme, written out, and reproduces it.
  * --container: fmpy's container FMU (fmpy.container_fmu). It transfers the connections one by one after
    each step in the order listed (CONNECTIONS, in the loop's order), so it runs the master loop bit for bit;
    see build_container for the workarounds it needed.
"""
from __future__ import annotations

import argparse
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
from cart_chain_reference import CartChain, simulate as simulate_reference  # noqa: E402
from cosim import Slave, finish, observed_orders, write_container  # noqa: E402

SCENE = HERE / "cart_chain.json"
HOOK = 1                      # 1-based mass number of the driven hook
RTOL = 1e-11                  # the chain FMU's dop853 tolerance, far below the coupling error
SAMPLE = 0.008                # errors compared at multiples of this time (every step size divides it)
CART_MASS = 1.0               # kg, the default: as heavy as the chain
STARTUP = 0.1                 # s: acceleration errors are compared from here on (see errors)
A_BLOWN_UP = 1000.0           # m/s2: a master stops when the cart's |a| passes this (~100 g; the motion's is < 2 g)


class CouplingFailed(Exception):
    """An FMU refused a step (or the state left every sane range): the coupling blew up at time t."""

    def __init__(self, t, why):
        super().__init__(f"t = {t:.6g} s: {why}")
        self.t = t


# ---------------------------------------------------------------------------- the scene and the reference
def chain_model(scene_path=SCENE, m_c=CART_MASS) -> tuple[CartChain, np.ndarray]:
    """The reference model of the scene (masses, link lengths, gravity) and its initial angles, read from the
    scene file; refuses a scene that is not a planar chain hanging from a hook at the origin in the x-z plane."""
    scene = ln.load_scene(scene_path)
    X0 = scene.X0
    if list(scene.driven_indices) != [HOOK - 1] or np.any(X0[HOOK - 1] != 0):
        raise ValueError(f"{scene_path}: mass {HOOK} must be the only driven anchor, at the origin")
    n = scene.K - 1
    if [(int(a), int(b)) for a, b in zip(scene.k1, scene.k2)] != [(k, k + 1) for k in range(n)]:
        raise ValueError(f"{scene_path}: the links must join masses 1-2, 2-3, ... in order (a hanging chain)")
    if np.any(X0[:, 1] != 0) or np.any(scene.gravity[:2] != 0):
        raise ValueError(f"{scene_path}: the chain must lie in the x-z plane with gravity along -z")
    d = np.diff(X0, axis=0)
    theta0 = np.arctan2(d[:, 0], -d[:, 2])
    model = CartChain(m_c, scene.mass[1:], scene.length, g=float(-scene.gravity[2]))
    return model, theta0


def reference(m_c, t_end, sample=SAMPLE, scene_path=SCENE) -> dict:
    """The monolithic cart-and-chain run at t = 0, sample, ..., t_end (cart_chain_reference)."""
    model, theta0 = chain_model(scene_path, m_c)
    t = np.arange(int(round(t_end / sample)) + 1) * sample
    return simulate_reference(model, np.r_[0.0, theta0], np.zeros(model.n + 1), t)


# ---------------------------------------------------------------------------- FMUs and the master
def build(out: Path, native=True) -> dict:
    """The cart FMU (pythonfmu) and the chain FMU (native C core, or pythonfmu with native=False)."""
    out.mkdir(parents=True, exist_ok=True)
    tag = "native" if native else "python"
    return dict(cart=build_fmu.build_component_fmu("cart", out / "cart.fmu", quiet=True),
                chain=build_fmu.build_scene_fmu(SCENE, out / f"cart_chain_{tag}.fmu", integrator="dop853",
                                                tolerance=RTOL, native=native, quiet=True))


def _chain_names(n):
    return [f"X[{k},{i}]" for k in range(HOOK + 1, HOOK + n + 1) for i in (1, 3)]


def master(fmus: dict, m_c: float, h: float, t_end: float, scheme: str = "cart-first", sample=SAMPLE) -> dict:
    """The explicit coupling loop (cosim.Slave). Returns, every `sample` s, the cart's x and the chain masses'
    x, z (X, shape (n_t, n, 2)); every step, the cart's a (`a_steps`). `failed`: the time at which an FMU
    refused a step (the run stops there), else None.

    scheme "cart-first" (the module doc's loop); "jacobi": each FMU's outputs read right after its own doStep,
    as fmpy's SSP simulator does (the hook's A is the cart's previous a, the cart's first force 0)."""
    model, _ = chain_model(m_c=m_c)
    n = model.n
    cart = Slave(fmus["cart"], "cart", start={"mass": m_c})
    chain = Slave(fmus["chain"], "chain")
    steps = int(round(t_end / h))
    every = int(round(sample / h))
    xs, Xs, a_steps = [], [], []
    names = _chain_names(n)
    failed = None
    start = time.perf_counter()
    held = dict(F=0.0, x=0.0, v=0.0, a=0.0)  # the jacobi scheme's connector values (fmpy's start at 0)
    try:
        for k in range(steps + 1):
            t = k * h
            if scheme == "cart-first":
                # every input known before an output that depends on it is read: x, v are states, so the hook's
                # P, V are set before Freact is read (with A still the last step's: the hold's end)
                x, v = cart.get(["x", "v"])
                chain.set({"P[1,1]": x, "V[1,1]": v})
                cart.set({"F": chain.get(["Freact[1,1]"])[0]})
                a = cart.get(["a"])[0]
                chain.set({"A[1,1]": a})
            else:
                cart.set({"F": held["F"]})
                chain.set({"P[1,1]": held["x"], "V[1,1]": held["v"], "A[1,1]": held["a"]})
                x, a = cart.get(["x", "a"])
            a_steps.append(a)
            if k % every == 0:
                xs.append(x)
                Xs.append(chain.get(names).reshape(n, 2))
            if k == steps:
                break
            if not abs(a) < A_BLOWN_UP:
                raise CouplingFailed(t, f"the cart's acceleration is {a:.3g} m/s2")
            try:
                cart.step(t, h)
                chain.step(t, h)
            except Exception as exc:  # fmpy raises on fmi2Discard / fmi2Error
                raise CouplingFailed(t, f"a doStep was refused ({exc})") from None
            if scheme == "jacobi":
                held["x"], held["v"], held["a"] = cart.get(["x", "v", "a"])
                held["F"] = chain.get(["Freact[1,1]"])[0]
    except CouplingFailed as exc:
        failed = exc.t
    wall = time.perf_counter() - start
    close_quietly(cart, chain)
    return dict(x=np.array(xs), X=np.array(Xs), a_steps=np.array(a_steps), h=h, failed=failed, wall=wall)


def close_quietly(*slaves) -> None:
    """Close every slave, even after a refused step (an instance that refused a step may refuse terminate too)."""
    for s in slaves:
        try:
            s.close()
        except Exception:
            pass


def library_master(m_c: float, h: float, t_end: float, sample=SAMPLE) -> dict:
    """The cart-first loop with no FMU: linknet_core.Simulator(anchors=) for the chain, the cart's closed form."""
    scene = ln.load_scene(SCENE)
    sim = ln.Simulator(scene, method="dop853", rtol=RTOL)
    P0 = scene.X0[HOOK - 1]
    steps = int(round(t_end / h))
    every = int(round(sample / h))
    x = v = a_held = 0.0
    xs, Xs, a_steps = [], [], []
    failed = None
    start = time.perf_counter()
    for k in range(steps + 1):
        t = k * h
        hook = (np.array([[x + P0[0], P0[1], P0[2]]]), np.array([[v, 0.0, 0.0]]), np.array([[a_held, 0.0, 0.0]]))
        F = sim.outputs(anchors=hook)["Freact"][0, 0]
        a = F / m_c
        a_steps.append(a)
        if k % every == 0:
            xs.append(x)
            Xs.append(sim.state.X[HOOK:, [0, 2]].copy())
        if k == steps:
            break
        if not abs(a) < A_BLOWN_UP:
            failed = t
            break
        try:
            sim.advance((k + 1) * h, anchors=(hook[0], hook[1], np.array([[a, 0.0, 0.0]])))
        except ln.SolverError:  # e.g. the step size underflows under a blown-up hook acceleration
            failed = t
            break
        x, v, a_held = x + v * h + 0.5 * a * h * h, v + a * h, a
    return dict(x=np.array(xs), X=np.array(Xs), a_steps=np.array(a_steps), h=h, failed=failed,
                wall=time.perf_counter() - start)


def errors(run: dict, ref: dict) -> dict:
    """position: max over the samples of the largest distance (cart or chain mass) from the reference (m);
    acceleration: max |a - a_ref| of the cart at the samples from t = STARTUP on (m/s2). Before, a carries the
    start-up error: the first Freact is computed for a hook at rest, so a_0 is off by F0 m_eff / (m_c (m_c +
    m_eff)) whatever h, and that error decays by m_eff/m_c per step."""
    m = min(len(run["x"]), len(ref["x"]))
    d_cart = np.abs(run["x"][:m] - ref["x"][:m])
    d_chain = np.linalg.norm(run["X"][:m] - ref["P"][:m], axis=2).max(axis=1)
    every = int(round(SAMPLE / run["h"]))
    a = run["a_steps"][::every][:m]
    late = ref["t"][:m] >= STARTUP - 1e-12
    return dict(position=float(max(d_cart.max(), d_chain.max())),
                acceleration=float(np.max(np.abs(a - ref["a"][:m])[late])))


# ---------------------------------------------------------------------------- stability
def growth(run: dict, ref_fine: dict) -> float:
    """How much the coupling's acceleration error grew: max_n |a_n - a_ref(t_n)| / |a_0 - a_ref(0)|, over every
    communication point (ref_fine sampled at every step). Stable coupling: <= 1 (the start-up error, made in
    the first step when Freact was computed for a hook at rest, only decays); unstable: > 1."""
    e = run["a_steps"] - ref_fine["a"][:len(run["a_steps"])]
    return float(np.max(np.abs(e)) / abs(e[0]))


def stable(run_loop, ratio, h, t_end, m_chain) -> tuple[bool, dict]:
    """run_loop(m_c, h, t_end) -> a master's result (master, library_master)."""
    m_c = ratio * m_chain
    run = run_loop(m_c, h, t_end)
    if run["failed"] is not None:
        return False, dict(run=run, growth=np.inf)
    ref = reference(m_c, t_end, sample=h)
    g = growth(run, ref)
    return g <= 1.0 + 1e-9, dict(run=run, growth=g)


def stability_limit(run_loop, h, t_end, m_chain, lo=0.05, hi=1.0, rel=0.005) -> float:
    """The smallest m_c/m_chain at which the coupling is stable (growth <= 1), by bisection in log(ratio)
    between lo (unstable) and hi (stable), to a relative width `rel`."""
    if not stable(run_loop, hi, h, t_end, m_chain)[0] or stable(run_loop, lo, h, t_end, m_chain)[0]:
        raise ValueError(f"the limit is not between m_c/m_chain = {lo} and {hi} at h = {h}")
    while hi / lo > 1 + rel:
        mid = np.sqrt(lo * hi)
        if stable(run_loop, mid, h, t_end, m_chain)[0]:
            hi = mid
        else:
            lo = mid
    return float(np.sqrt(lo * hi))


# ---------------------------------------------------------------------------- fmpy's SSP simulator
# in the order of the cart-first loop: fmpy's container FMU transfers its connections one by one in this order
# after each step (an output read after the inputs it depends on were set); the SSP simulator's order is its own
CONNECTIONS = [("cart", "x", "chain", "P[1,1]"), ("cart", "v", "chain", "V[1,1]"),
               ("chain", "Freact[1,1]", "cart", "F"), ("cart", "a", "chain", "A[1,1]")]


def write_ssp(fmus: dict, path: Path) -> Path:
    """An SSP 1.0 archive of the two FMUs and their 4 connections."""
    connectors = {"cart": [], "chain": []}
    for s_el, s_con, e_el, e_con in CONNECTIONS:
        connectors[s_el].append((s_con, "output"))
        connectors[e_el].append((e_con, "input"))
    n = chain_model()[0].n
    connectors["chain"] += [(name, "output") for name in _chain_names(n)]  # recorded by the simulator
    elements = []
    for name in ("cart", "chain"):
        cons = "".join(f'<ssd:Connector name="{c}" kind="{k}"><ssc:Real/></ssd:Connector>'
                       for c, k in connectors[name])
        elements.append(f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" '
                        f'source="resources/{name}.fmu"><ssd:Connectors>{cons}</ssd:Connectors></ssd:Component>')
    connections = "".join(f'<ssd:Connection startElement="{a}" startConnector="{b}" endElement="{c}" '
                          f'endConnector="{d}"/>' for a, b, c, d in CONNECTIONS)
    ssd = ('<?xml version="1.0" encoding="UTF-8"?>'
           '<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
           'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="cart_chain">'
           f'<ssd:System name="cart_chain"><ssd:Elements>{"".join(elements)}</ssd:Elements>'
           f'<ssd:Connections>{connections}</ssd:Connections></ssd:System></ssd:SystemStructureDescription>')
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        for name in ("cart", "chain"):
            z.write(fmus[name], f"resources/{name}.fmu")
    return path


def ssp_master(fmus: dict, m_c: float, h: float, t_end: float, out: Path, sample=SAMPLE) -> dict:
    """fmpy's SSP simulator. It records each row after the step that starts at the row's time (row n holds
    the outputs at t_n + h): prepended with the initial state to align with t = 0, h, 2h ..."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet
    ssp = write_ssp(fmus, out / "cart_chain.ssp")
    params = ParameterSet(name="cart")
    params.parameters = [Parameter(name="cart.mass", type="Real", value=m_c)]
    start = time.perf_counter()
    # stop slightly past t_end: fmpy's loop runs `while time < stop_time` with time += h
    res = simulate_ssp(str(ssp), stop_time=t_end + 0.5 * h, step_size=h, parameter_set=params)
    wall = time.perf_counter() - start
    model, theta0 = chain_model(m_c=m_c)
    n = model.n
    every = int(round(sample / h))
    X0 = model.positions(np.r_[0.0, theta0])
    x = np.r_[0.0, res["cart.x"]][::every]
    X = np.concatenate([X0[None], np.stack([np.stack([res[f"chain.X[{k},{i}]"] for i in (1, 3)], 1)
                                            for k in range(HOOK + 1, HOOK + n + 1)], 1)])[::every]
    a_steps = np.asarray(res["cart.a"])  # read after the step from t_n: the cart's a over that step, a_n
    n_samples = int(round(t_end / sample)) + 1
    return dict(x=x[:n_samples], X=X[:n_samples], a_steps=a_steps, h=h, failed=None, wall=wall)


# ---------------------------------------------------------------------------- fmpy's container FMU
def build_container(fmus: dict, m_c: float, h: float, out: Path) -> Path:
    """An fmpy container FMU of the composition: outputs x, a (the cart's) and the chain's X[k,1], X[k,3];
    parameter mass (the cart's). The workarounds pd_feedback.build_container documents (fmpy 0.3.32): connection
    types "Real" -> "Float64" in resources/container.json, and a first variable "time" (value reference 0 reads
    back as time)."""
    import uuid
    from fmpy import read_model_description
    from fmpy.container_fmu import Configuration
    from fmpy.container_fmu.config import Component, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    md = {name: read_model_description(str(fmus[name])) for name in ("cart", "chain")}
    var = {name: {v.name: v for v in md[name].modelVariables} for name in md}
    comp = {name: Component(name=name, filename=Path(fmus[name]), modelDescription=md[name]) for name in md}
    conns = [Connection(startElement=comp[a], startConnectors=[var[a][b]], endElement=comp[c],
                        endConnectors=[var[c][d]]) for a, b, c, d in CONNECTIONS]

    def output(name, description):
        return ModelVariable(name=name, type="Real", causality="output", variability="continuous",
                             initial="calculated", description=description)

    n = chain_model()[0].n
    time_var = ModelVariable(name="time", type="Real", causality="independent", variability="continuous")
    outputs = {("cart", "x"): output("x", "the cart's position (m)"),
               ("cart", "a"): output("a", "the cart's acceleration (m/s2)")}
    outputs.update({("chain", name): output(name, "a chain mass's coordinate (m)") for name in _chain_names(n)})
    mass = ModelVariable(name="mass", type="Real", causality="parameter", variability="tunable", initial="exact",
                         description="the cart's mass (kg)")
    mass.start = repr(float(m_c))
    token = "{" + str(uuid.uuid4()) + "}"
    variables = [time_var, *outputs.values(), mass]
    container = ModelDescription(fmiVersion="2.0", modelName="cart_chain", instantiationToken=token,
                                 coSimulation=CoSimulation(modelIdentifier="container_fmu", fixedInternalStepSize=h),
                                 modelVariables=variables,
                                 defaultExperiment=DefaultExperiment(startTime="0", stopTime="2", stepSize=repr(h)))
    container.guid = token  # FMI 2 name of the instantiation token
    container.outputs = [Unknown(index=i + 2, variable=v) for i, v in enumerate(outputs.values())]
    container.initialUnknowns = list(container.outputs)
    mapping = {v: [(comp[c], var[c][name])] for (c, name), v in outputs.items()}
    mapping[mass] = [(comp["cart"], var["cart"]["mass"])]
    config = Configuration(parallelDoStep=False, modelDescription=container, components=list(comp.values()),
                           connections=conns, variableMappings=mapping)
    return write_container(config, out, "cart_chain_container")


def run_container(fmus: dict, m_c: float, h: float, t_end: float, out: Path, sample=SAMPLE) -> dict:
    """fmpy.simulate_fmu on the container FMU, sampled like the masters."""
    import fmpy
    fmu = build_container(fmus, m_c, h, out)
    n = chain_model()[0].n
    names = _chain_names(n)
    start = time.perf_counter()
    res = fmpy.simulate_fmu(str(fmu), stop_time=t_end, output_interval=h, output=["x", "a", *names])
    wall = time.perf_counter() - start
    every = int(round(sample / h))
    X = np.stack([res[name] for name in names], 1).reshape(-1, n, 2)
    n_samples = int(round(t_end / sample)) + 1
    return dict(x=res["x"][::every][:n_samples], X=X[::every][:n_samples], a_steps=np.asarray(res["a"]), h=h,
                failed=None, wall=wall)


# ---------------------------------------------------------------------------- main
def _table(rows, header):
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    line = lambda r: "  | " + " | ".join(str(c).rjust(w) for c, w in zip(r, widths)) + " |"  # noqa: E731
    print(line(header))
    print("  |" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in rows:
        print(line(r))


def convergence(label, run, steps, m_c, t_end):
    ref = reference(m_c, t_end)
    rows, pos = [], []
    for h in steps:
        r = run(h)
        e = errors(r, ref)
        pos.append(e["position"])
        rows.append([f"{h:g}", f"{e['position']:.3e}", f"{e['acceleration']:.3e}", f"{r['wall']:.2f}"])
    orders = observed_orders(steps, pos) if len(steps) > 1 else []
    for row, o in zip(rows[1:], orders):
        row.insert(2, f"{o:.2f}")
    rows[0].insert(2, "")
    print(f"{label}: m_c = {m_c:g} kg, t_end = {t_end:g} s")
    _table(rows, ["h (s)", "max position error (m)", "order", f"max |a - a_ref|, t >= {STARTUP:g} s (m/s2)",
                 "wall (s)"])
    return pos, orders


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--h", type=float, nargs="+", default=[0.008, 0.004, 0.002, 0.001])
    p.add_argument("--t-end", type=float, default=2.0)
    p.add_argument("--cart-mass", type=float, default=CART_MASS)
    p.add_argument("--kind", choices=("native", "python", "both"), default="native", help="the chain FMU's kind")
    p.add_argument("--library", action="store_true", help="also run the loop on linknet_core.Simulator, no FMU")
    p.add_argument("--ssp", action="store_true", help="also run fmpy's SSP simulator")
    p.add_argument("--container", action="store_true", help="also run fmpy's container FMU")
    p.add_argument("--stability", action="store_true",
                   help="the smallest stable m_c/m_chain for each h (bisection) and errors on a grid of ratios")
    p.add_argument("--out", default=str(ROOT / "build" / "compositions"))
    a = p.parse_args(argv)
    out = Path(a.out)
    model, theta0 = chain_model(m_c=a.cart_mass)
    m_chain = float(model.mu[0])
    m_eff0 = model.added_mass(np.r_[0, theta0])
    print(f"cart (fmu_src/cart.py) + chain ({SCENE.name}: {model.n} masses, {m_chain:g} kg, hook = driven mass "
          f"{HOOK}); released straight at {theta0[0]:.3g} rad: added mass m_eff = {m_eff0:.4g} kg at t = 0")
    kinds = {"native": [True], "python": [False], "both": [True, False]}[a.kind]
    fmus = {native: build(out, native) for native in kinds}
    for native in kinds:
        convergence(f"master loop, cart first ({'native' if native else 'pythonfmu'} chain FMU)",
                    lambda h: master(fmus[native], a.cart_mass, h, a.t_end), a.h, a.cart_mass, a.t_end)
    main_fmus = fmus[kinds[0]]
    if a.library:
        convergence("the same loop on linknet_core.Simulator(anchors=)",
                    lambda h: library_master(a.cart_mass, h, a.t_end), a.h, a.cart_mass, a.t_end)
    if a.ssp:
        convergence("fmpy SSP simulator (Jacobi)", lambda h: ssp_master(main_fmus, a.cart_mass, h, a.t_end, out),
                    a.h, a.cart_mass, a.t_end)
        convergence("master loop, scheme 'jacobi' (what the SSP simulator does)",
                    lambda h: master(main_fmus, a.cart_mass, h, a.t_end, scheme="jacobi"), a.h, a.cart_mass, a.t_end)
    if a.container:
        convergence("fmpy container FMU", lambda h: run_container(main_fmus, a.cart_mass, h, a.t_end, out),
                    a.h, a.cart_mass, a.t_end)
    if a.stability:
        print(f"stability of the explicit coupling (t_end = {a.t_end:g} s): growth = max |a_n - a_ref| / "
              f"|a_0 - a_ref(0)|; stable when <= 1. Predicted limit (h -> 0): m_c / m_chain = max m_eff / m_chain = "
              f"{m_eff0 / m_chain:.4f}")
        ratios = [0.6, 0.45, 0.42, 0.40, 0.38, 0.35, 0.30, 0.25, 0.20, 0.10]
        rows = []
        loop = lambda m_c, h, t_end: master(main_fmus, m_c, h, t_end)  # noqa: E731
        for h in a.h:
            row = [f"{h:g}"]
            for r in ratios:
                ok, info = stable(loop, r, h, a.t_end, m_chain)
                run = info["run"]
                row.append("blown up at %.3g s" % run["failed"] if run["failed"] is not None
                           else f"{info['growth']:.3g}")
            row.append(f"{stability_limit(loop, h, a.t_end, m_chain):.4f}")
            rows.append(row)
        print("  growth at m_c / m_chain = (columns), and the limit found by bisection (to 0.5 %):")
        _table(rows, ["h (s)"] + [f"{r:g}" for r in ratios] + ["limit"])
    return 0


if __name__ == "__main__":
    finish(main())
