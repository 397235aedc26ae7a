"""fmi2GetDirectionalDerivative of both FMU kinds (native C core; pythonfmu through its front layer): the interface
Jacobian of every output with respect to every input at the current state, after a few communication steps with
inputs, checked against

* central differences of the FMU's own outputs (an input set +- delta and T, Freact read back without a step: direct
  feedthrough), an independent reference;
* linknet_core's Simulator.interface_jacobian at the same state, run here with the same inputs.

X, U, Jreact and error_estimate have no direct feedthrough: their derivatives are 0. References that are not an
output (unknown) or an input (known), and calls before initialization ends, are refused with fmi2Error naming them,
and the instance stays usable. The scenes: chain_10, net_10x10, a chain hanging from an input-driven anchor (with a
fixed pivot and an anchor driven by a scene motion), and the redundant truss (minimum-norm tensions: the derivative
of the pseudo-inverse) with one of its supports an input-driven anchor (held still: a rigid truss cannot follow it),
and a free rigid body (spinning_tetrahedron: the native FMU's rigid-body specialisation).

Each FMU is driven in a subprocess client (the pythonfmu FMU embeds this Python), built once per module."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "examples" / "compositions"))
import driven_fmu_support as drive  # noqa: E402
from driven_anchor_scenes import drive as driven  # noqa: E402
import linknet_core as ln  # noqa: E402
from fmu_harness import build_cached, run_client  # noqa: E402

KINDS = ("native", "python")
SCENES = ("chain_10", "net_10x10", "driven_chain", "redundant_truss_driven", "spinning_tetrahedron")
H = 0.01
N_STEPS = 3
# the input motion of an input-driven anchor: P0 + V0 t + A0 t^2 / 2, set (P, V, A) at every communication point
V0 = np.array([0.3, 0.0, -0.2])
A0 = np.array([1.0, 0.0, 0.5])
# central-difference steps per input kind: T and Freact are affine in F and A, quadratic in V (exact central
# differences), and smooth in P (truncation ~ delta^2)
DELTA = {"F": 0.5, "P": 1e-4, "V": 0.1, "A": 1.0}


# scenes whose input-driven anchor is held still (V = A = 0 at its initial position)
STILL = {"redundant_truss_driven"}


def scene_path(name: str, root: Path) -> Path:
    if name in drive.SCENES:
        return drive.write_scene(root, name)
    if name == "redundant_truss_driven":  # its first support (w0) an input-driven anchor
        path = root / f"{name}.json"
        scene = driven(ln.load_scene(str(ROOT / "models" / "redundant_truss.json")), 0, None, name=name)
        path.write_text(json.dumps(scene.to_dict()))
        return path
    return ROOT / "models" / f"{name}.json"


def input_force(k: int, i: int, t: float) -> float:
    """A force input on mass k (0-based), axis i, at the communication point t: varied per mass, axis and time."""
    return 0.4 * np.sin(1.3 * k + 2.1 * i + 7.0 * t)


def anchor_motion(scene: ln.Scene, t: float):
    """(P, V, A) of the input-driven anchors at t, each (n, 3)."""
    P0 = np.asarray(scene.X0)[scene.input_driven_indices]
    V, A = (np.zeros(3), np.zeros(3)) if scene.name in STILL else (V0, A0)
    return P0 + V * t + 0.5 * A * t * t, np.broadcast_to(V + A * t, P0.shape).copy(), \
        np.broadcast_to(A, P0.shape).copy()


def inputs_at(scene: ln.Scene, t: float) -> dict:
    """The values of every input variable at the communication point t, by FMU variable name."""
    values = {}
    for k in scene.free_indices:
        for i in range(3):
            values[f"F[{k + 1},{i + 1}]"] = input_force(int(k), i, t)
    anchors = scene.input_driven_indices
    if len(anchors):
        P, V, A = anchor_motion(scene, t)
        for j, k in enumerate(anchors):
            for i in range(3):
                values[f"P[{k + 1},{i + 1}]"] = P[j, i]
                values[f"V[{k + 1},{i + 1}]"] = V[j, i]
                values[f"A[{k + 1},{i + 1}]"] = A[j, i]
    return values


def library_inputs(scene: ln.Scene, t: float):
    F = np.zeros((scene.K, 3))
    for k in scene.free_indices:
        F[k] = [input_force(int(k), i, t) for i in range(3)]
    anchors = scene.input_driven_indices
    hold = anchor_motion(scene, t) if len(anchors) else None
    return F, hold


CLIENT = """
import json
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks
fmu_path, steps, final, delta, h = {fmu!r}, json.loads({steps!r}), json.loads({final!r}), {delta!r}, {h!r}
md = read_model_description(fmu_path)
where = extract(fmu_path)
vr = {{v.name: v.valueReference for v in md.modelVariables}}
causality = {{v.name: v.causality for v in md.modelVariables}}
log = []
def logger(env, instance, status, category, message):
    log.append((int(status), message.decode("utf-8", "replace")))
callbacks = fmi2CallbackFunctions()
callbacks.logger = fmi2CallbackLoggerTYPE(logger)
callbacks.allocateMemory = defaultCallbacks.allocateMemory
callbacks.freeMemory = defaultCallbacks.freeMemory
def instance(name):
    s = FMU2Slave(guid=md.guid, unzipDirectory=where, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=name)
    s.instantiate(callbacks=callbacks, loggingOn=False)
    return s
def refused(call):
    before = len(log)
    try:
        call()
    except Exception:
        return " | ".join(m for s, m in log[before:] if s >= 3) or "(refused, nothing logged)"
    return ""

inputs = [v.name for v in md.modelVariables if v.causality == "input"]
outputs = [v.name for v in md.modelVariables if v.causality == "output"]
feedthrough = [n for n in outputs if n.startswith(("T[", "Freact["))]
s = instance("jacobian")
s.setupExperiment(startTime=0.0)
s.enterInitializationMode()
early_init = refused(lambda: s.getDirectionalDerivative([vr[feedthrough[0]]], [vr[inputs[0]]], [1.0]))
s.exitInitializationMode()
t = 0.0
for values in steps:
    s.setReal([vr[n] for n in values], list(values.values()))
    s.doStep(t, h)
    t += h
s.setReal([vr[n] for n in final], list(final.values()))
out_vr = [vr[n] for n in outputs]
fd_vr = [vr[n] for n in feedthrough]
J = np.zeros((len(outputs), len(inputs)))
for j, name in enumerate(inputs):
    J[:, j] = s.getDirectionalDerivative(out_vr, [vr[name]], [1.0])
# one call with a seed on every input at once: J times the seed (one seed, one solve)
rng = np.random.default_rng(7)
seed = rng.standard_normal(len(inputs))
combined = np.array(s.getDirectionalDerivative(out_vr, [vr[n] for n in inputs], list(seed)))
no_seed = np.array(s.getDirectionalDerivative(out_vr, [], []))  # no known: the derivative along a zero seed
# central differences of the FMU's own outputs: an input moved, the outputs read, no step
FD = np.zeros((len(feedthrough), len(inputs)))
steps_used = np.zeros(len(inputs))
for j, name in enumerate(inputs):
    d = delta[name.split("[")[0]]
    v0 = final[name]
    s.setReal([vr[name]], [v0 + d])
    up = np.array(s.getReal(fd_vr))
    s.setReal([vr[name]], [v0 - d])
    down = np.array(s.getReal(fd_vr))
    s.setReal([vr[name]], [v0])
    FD[:, j] = (up - down) / (2.0 * d)
    steps_used[j] = d
X = np.array(s.getReal([vr[n] for n in outputs if n.startswith("X[")]))
U = np.array(s.getReal([vr[n] for n in outputs if n.startswith("U[")]))
feed_now = np.array(s.getReal(fd_vr))
# refusals: a parameter or an output as a known, an input or a parameter as an unknown, an unknown reference, a
# seed that is not finite; the instance goes on answering
parameter = next(v.name for v in md.modelVariables if v.causality == "parameter")
bad = [refused(lambda: s.getDirectionalDerivative([fd_vr[0]], [vr[parameter]], [1.0])),
       refused(lambda: s.getDirectionalDerivative([fd_vr[0]], [vr[outputs[0]]], [1.0])),
       refused(lambda: s.getDirectionalDerivative([vr[inputs[0]]], [vr[inputs[0]]], [1.0])),
       refused(lambda: s.getDirectionalDerivative([vr[parameter]], [vr[inputs[0]]], [1.0])),
       refused(lambda: s.getDirectionalDerivative([fd_vr[0]], [99999], [1.0])),
       refused(lambda: s.getDirectionalDerivative([fd_vr[0]], [vr[inputs[0]]], [float("nan")]))]
again = np.array(s.getDirectionalDerivative(out_vr, [vr[inputs[0]]], [1.0]))
s.terminate()
s.freeInstance()
fresh = instance("before_init")
early_instantiated = refused(lambda: fresh.getDirectionalDerivative([vr[feedthrough[0]]], [vr[inputs[0]]], [1.0]))
fresh.freeInstance()
save(J=J, combined=combined, seed=seed, no_seed=no_seed, FD=FD, steps_used=steps_used, X=X, U=U, t=np.array(t), again=again,
     feed_now=feed_now, inputs=np.array(inputs), outputs=np.array(outputs), feedthrough=np.array(feedthrough),
     bad=np.array(bad), bad_names=np.array([parameter, outputs[0], inputs[0], parameter, "99999", inputs[0]]),
     early=np.array([early_init, early_instantiated]),
     provides=np.array(bool(md.coSimulation.providesDirectionalDerivative)))
"""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    root = tmp_path_factory.mktemp("directional")
    return {(name, kind): build_cached(root, str(scene_path(name, root)), native=kind == "native")
            for name in SCENES for kind in KINDS}, root


def scene_of(name: str, root: Path) -> ln.Scene:
    return ln.load_scene(str(scene_path(name, root)))


def run_fmu(fmu: Path, scene: ln.Scene, workdir: Path) -> dict:
    steps = [inputs_at(scene, n * H) for n in range(N_STEPS)]
    final = inputs_at(scene, N_STEPS * H)
    return run_client(CLIENT.format(fmu=str(fmu), steps=json.dumps(steps), final=json.dumps(final), delta=DELTA,
                                    h=H), workdir)


def library_jacobian(scene: ln.Scene, fmu_X: np.ndarray, fmu_U: np.ndarray, inputs, outputs) -> np.ndarray:
    """Simulator.interface_jacobian after the same steps with the same inputs, at its own state (which is the FMU's
    to round-off, asserted), as a matrix (outputs x inputs) in the FMU's variable order."""
    sim = ln.Simulator(scene)
    for n in range(N_STEPS):
        F, hold = library_inputs(scene, n * H)
        sim.advance((n + 1) * H, F, anchors=hold)
    np.testing.assert_allclose(sim.state.X.reshape(-1), fmu_X, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sim.state.U.reshape(-1), fmu_U, rtol=0, atol=1e-9)
    F, hold = library_inputs(scene, N_STEPS * H)
    blocks = sim.interface_jacobian(F, anchors=hold)
    anchored = list(scene.fixed_indices)
    driven = list(scene.input_driven_indices)
    J = np.zeros((len(outputs), len(inputs)))
    for a, out in enumerate(outputs):
        kind, index = out.split("[")[0], [int(x) - 1 for x in out.rstrip("]").split("[")[1].split(",")] \
            if "[" in out else []
        if kind not in ("T", "Freact"):
            continue  # no direct feedthrough: zero
        for b, name in enumerate(inputs):
            which, (k, i) = name.split("[")[0], [int(x) - 1 for x in name.rstrip("]").split("[")[1].split(",")]
            block = blocks[kind, which]
            column = (k, i) if which == "F" else (driven.index(k), i)
            J[a, b] = block[(index[0], *column)] if kind == "T" else block[(anchored.index(index[0]), index[1],
                                                                             *column)]
    return J


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", SCENES)
def test_directional_derivatives_against_differences_and_the_library(fmus, name, kind, tmp_path):
    built, root = fmus
    scene = scene_of(name, root)
    r = run_fmu(built[name, kind], scene, tmp_path / "client")
    assert bool(r["provides"])
    inputs, outputs, feedthrough = list(r["inputs"]), list(r["outputs"]), list(r["feedthrough"])
    J = r["J"]
    rows = [outputs.index(n) for n in feedthrough]
    # no direct feedthrough: X, U, Jreact, error_estimate answer 0 to every seed
    others = [a for a, n in enumerate(outputs) if n not in feedthrough]
    assert others and np.all(J[others] == 0.0)
    Jf = J[rows]
    assert np.all(np.isfinite(Jf)) and np.abs(Jf).max() > 0
    # central differences of the FMU's own outputs, column by column (each input kind in its own units)
    FD = r["FD"]
    level = np.abs(r["feed_now"]).max()
    for b, name_in in enumerate(inputs):
        scale = np.abs(Jf[:, b]).max()
        tol = 1e-6 * scale + 1e-12 * level / r["steps_used"][b]
        worst = np.abs(FD[:, b] - Jf[:, b]).max()
        assert worst <= tol, f"{name}/{kind}: d/d{name_in}: central differences differ by {worst:.3g} > {tol:.3g}"
    # the same derivatives from the library at the same state (the C core or the numpy reference)
    ref = library_jacobian(scene, r["X"], r["U"], inputs, outputs)
    scale = np.abs(ref[rows]).max(axis=0)
    np.testing.assert_allclose(J, ref, rtol=0, atol=1e-10 * max(scale.max(), 1.0), err_msg=f"{name}/{kind}")
    # one call with a seed on every input is the Jacobian times the seed; a repeated call the same column
    np.testing.assert_allclose(r["combined"], J @ r["seed"], rtol=0,
                               atol=1e-11 * np.abs(J).max() * np.abs(r["seed"]).sum())
    np.testing.assert_array_equal(r["again"], J[:, 0])
    assert np.all(r["no_seed"] == 0.0)


@pytest.mark.parametrize("kind", KINDS)
def test_bad_references_and_calls_before_initialization_are_refused_naming_them(fmus, kind, tmp_path):
    built, root = fmus
    scene = scene_of("driven_chain", root)
    r = run_fmu(built["driven_chain", kind], scene, tmp_path / "client")
    roles = ["is a parameter, not an input", "is an output, not an input", "is an input, not an output",
             "is a parameter, not an output", "not a Real variable of this FMU", "a seed must be finite"]
    for message, name, role in zip(r["bad"], r["bad_names"], roles):
        assert role in message and name in message, (kind, name, message)
    for message in r["early"]:
        assert "fmi2GetDirectionalDerivative" in message and "fmi2ExitInitializationMode" in message, (kind, message)


def test_only_the_network_fmus_declare_directional_derivatives(fmus, tmp_path):
    """The cart component answers no fmi2GetDirectionalDerivative, so its modelDescription must not declare it (a
    master asks every FMU that does: cart_chain_implicit.FmuSlave)."""
    from fmpy import read_model_description
    built, _ = fmus
    for (name, kind), path in built.items():
        assert read_model_description(str(path)).coSimulation.providesDirectionalDerivative, (name, kind)
    cart = build_cached(tmp_path, "cart")
    assert not read_model_description(str(cart)).coSimulation.providesDirectionalDerivative


@pytest.mark.parametrize("kind", KINDS)
def test_the_implicit_master_takes_the_chain_fmus_directional_derivative(tmp_path, kind):
    """cart_chain_implicit's FmuSlave uses fmi2GetDirectionalDerivative of the chain FMU (and the secant for the
    cart, which has none): the chain's dFreact/dA and dFreact/dV (quadratic in V: no secant stands for it) at the
    release equal the library's (Simulator.interface_linearization)."""
    import cart_chain as cc
    import cart_chain_implicit as ci
    fmus = {"cart": build_cached(tmp_path, "cart"),
            "chain": build_cached(tmp_path, str(cc.SCENE), integrator="dop853", tolerance=cc.RTOL,
                                  native=kind == "native")}
    ratio = 0.03
    out = run_client(f"""
sys.path.insert(0, {str(ROOT / "examples" / "compositions")!r})
import cart_chain_implicit as ci
cart, chain = ci.fmu_slaves({{"cart": {str(fmus["cart"])!r}, "chain": {str(fmus["chain"])!r}}}, {ratio!r})
chain.set({{"V[1,1]": 0.4, "A[1,1]": -1.5}})
save(provides=np.array([cart.provides_directional, chain.provides_directional]),
     dA=chain.directional(["Freact[1,1]", "Freact[1,3]"], ["A[1,1]"], [1.0]),
     dV=chain.directional(["Freact[1,1]", "Freact[1,3]"], ["V[1,1]"], [1.0]))
""", tmp_path / "client_master")
    assert list(out["provides"]) == [False, True]
    _, chain = ci.library_slaves(ratio)
    chain.set({"V[1,1]": 0.4, "A[1,1]": -1.5})
    dA = chain.directional(["Freact[1,1]", "Freact[1,3]"], ["A[1,1]"], [1.0])
    dV = chain.directional(["Freact[1,1]", "Freact[1,3]"], ["V[1,1]"], [1.0])
    np.testing.assert_allclose(out["dA"], dA, rtol=1e-10, atol=1e-12 * np.abs(dA).max())
    np.testing.assert_allclose(out["dV"], dV, rtol=1e-10, atol=1e-12 * np.abs(dV).max())
    assert np.abs(dA).max() > 0 and np.abs(dV).max() > 0
