#!/usr/bin/env python3
"""A Jacobian-corrected (linearly implicit) master for the cart carrying the chain: stable at any mass ratio.

    python examples/compositions/cart_chain_implicit.py [--ratios 1 0.3 0.1 0.03]
                                                        [--h 0.008 0.004 0.002 0.001 0.0005] [--t-end 1]
                                                        [--fmu [--kind native|python]]

The scene, the cart, the monolithic reference and the explicit loop are cart_chain.py's (imported). The explicit
loop hands the chain's Freact, computed with the last step's hook acceleration A, to the cart as its force: with
the chain's state held, Freact = F0 - m_eff A, so a_n = (F_drive + F0 - m_eff a_(n-1)) / m_c and every step
multiplies the error of a by -m_eff/m_c. It blows up at any communication step once m_c < m_eff (0.415 m_chain
at the release). This master closes that loop at each communication point with the interface Jacobians.

The loop. At a communication point the cart's x, v are states (no direct feedthrough): they are set as the hook's
P, V first, as in the explicit loop, and stay fixed. What is left is an algebraic loop between two direct
feedthroughs, the cart's a(F) and the chain's Freact(A) (at the current state and P, V):

    F = Freact(A),        A = a(F).

Linearise each side about the values held now, u_0 = (F_0, A_0) (the last step's), with y_0 = (Freact_0, a_0) the
outputs read at u_0 and J_A = dFreact/dA, D_F = da/dF the slaves' directional derivatives:

    Freact(A) ~ Freact_0 + J_A (A - A_0),        a(F) ~ a_0 + D_F (F - F_0).

Both are exact, not approximations, at a fixed state: the tensions solve A T = B (25) whose matrix does not depend
on the hook's acceleration and whose right-hand side (26) is linear in it, so Freact = C^T T is affine in A; the
cart's a = (F + F_drive)/m_c is affine in F. The loop u = y(u) is then the 2x2 linear system

    (I - J) u = y_0 - J u_0,        I - J = [[1, -J_A], [-D_F, 1]],   det = 1 - J_A D_F.

For the cart and chain, J_A = -m_eff (the chain's effective mass at the hook along the rail,
docs/interface_jacobians.md) and D_F = 1/m_c, so det = 1 + m_eff/m_c > 0 at every mass ratio, and eliminating F:

    (m_c + m_eff) a = F_drive + Freact_0 + m_eff A_0,     F = Freact_0 - m_eff (a - A_0),

the classic added-mass correction: the chain's inertia at the hook moves to the left-hand side, next to the
cart's. Freact_0 + m_eff A_0 is the chain's reaction at A = 0 (it does not depend on which A_0 was held), so a is
the acceleration of the monolithic system at this state: the Schur complement m_c + m_eff is the cart's row of the
monolithic mass matrix with the chain's angles eliminated (cart_chain_reference.CartChain.added_mass). The
lagged a_(n-1) is gone from the right-hand side: an error in a is multiplied by 0 per step instead of by
-m_eff/m_c. P and V need no Jacobian here: they are the cart's states, known before the loop is solved; dFreact/dP
and dFreact/dV would enter a master that also made the states implicit (iterating the step, with state rollback).

What remains is the zero-order hold: the cart's force, so the hook's acceleration, is held over [t, t + h] while
the true one changes. The master is a one-step method of the coupled system, first order in h; measured, it runs
at every h tried (0.008 s down) and every ratio (down to m_c = 0.03 m_chain), where the explicit loop is stable at
no h below m_c = m_eff. (Second order would need the hook's acceleration to change within the step, which neither
the cart's held force nor the chain's held P + V tau + A tau^2/2 can carry, or a step repeated from saved states.)

Slaves. The master sees each component through one interface (``CouplingSlave``): set, get and step by FMI
variable name, and ``directional(unknowns, knowns, seed)``, the derivative of the outputs ``unknowns`` along the
seed on the inputs ``knowns`` at the current state: what fmi2GetDirectionalDerivative gives. So the chain is one
line to swap:

    chain = SimulatorSlave(SCENE)                       # linknet_core.Simulator, Simulator.interface_linearization
    chain = FmuSlave(fmus["chain"], "chain")            # an FMU: fmi2GetDirectionalDerivative where it provides it

The cart is fmu_src/cart.py: its FMU (FmuSlave) or the same class run in this process (ComponentSlave). It provides
no directional derivatives, and a slave that provides none is differentiated by a secant of its own outputs (set
the input moved by the seed, read, restore: no step is taken), which is exact where the output is affine in the
input, as the cart's a(F) is; ``directional`` refuses it where a second secant disagrees.

Both chain FMU kinds provide directional derivatives: --fmu takes them through fmi2GetDirectionalDerivative
(FmuSlave uses it wherever the modelDescription declares it).

The tables (docs/interface_jacobians.md): for each m_c/m_chain, the implicit master's error against the monolithic
reference at each h and its order as h halves (and the explicit loop's, where it is stable); then, at every
(h, ratio), the explicit loop's growth (or the time it blew up) beside the implicit master's worst acceleration
error; the measured factor by which a change of the held A_0 moves the next a (explicit: -m_eff/m_c; implicit: 0
to round-off); and how much the monolithic motion itself amplifies an early error (``sensitivity``).

The run is 1 s, where cart_chain.py's is 2 s: the lighter carts' motion is itself sensitive late in the run (a
release 1e-4 rad off moves the 0.03 cart's chain 1.4e-3 m by 1.8 s and 1.6e-2 m by 2 s), so over 2 s a first-order
coupling error there reaches the asymptotic regime only at steps far below 0.00025 s (the table for 2 s shows it).
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

import cart_chain as cc  # noqa: E402
import linknet_core as ln  # noqa: E402
from cart_chain_reference import simulate as simulate_reference  # noqa: E402
from cosim import Slave, finish  # noqa: E402

RATIOS = (1.0, 0.3, 0.1, 0.03)   # m_c / m_chain of the tables
T_END = 1.0                       # s: the tables' run (see the module doc for 2 s)
AFFINE_RTOL = 1e-9                # a secant derivative is refused where a half seed's secant differs by more

# The connections with direct feedthrough at both ends: the algebraic loop the master solves. The others in
# cart_chain.CONNECTIONS start at the cart's states x, v (no direct feedthrough) and are set before it.
LOOP = [c for c in cc.CONNECTIONS if c[1] not in ("x", "v")]
STATES = [c for c in cc.CONNECTIONS if c not in LOOP]
FORCE, ACCELERATION = (LOOP.index(c) for c in (("chain", "Freact[1,1]", "cart", "F"), ("cart", "a", "chain", "A[1,1]")))


# ---------------------------------------------------------------------------- the slaves' interface
class CouplingSlave:
    """What the master asks of a component: ``set({name: value})``, ``get([names]) -> array``, ``step(t, h)``,
    ``close()`` and ``directional(unknowns, knowns, seed) -> array``, the derivative of the outputs ``unknowns``
    along ``seed`` on the inputs ``knowns`` at the current state and inputs (fmi2GetDirectionalDerivative's
    arguments, by name). This class gives ``directional`` by a secant of the slave's own outputs, for a slave that
    provides no derivatives: exact where they are affine in the seeded inputs, refused where not."""

    name = "slave"
    provides_directional = False

    def directional(self, unknowns, knowns, seed) -> np.ndarray:
        seed = np.asarray(seed, float)
        held = self.get(knowns)
        try:
            y0 = self.get(unknowns)
            self.set(dict(zip(knowns, held + seed)))
            y1 = self.get(unknowns)
            self.set(dict(zip(knowns, held + 0.5 * seed)))
            y_half = self.get(unknowns)
        finally:
            self.set(dict(zip(knowns, held)))
        d = y1 - y0
        if np.any(np.abs(2.0 * (y_half - y0) - d) > AFFINE_RTOL * (np.abs(y0) + np.abs(d))):
            raise ValueError(f"{self.name} provides no directional derivatives, and its outputs {list(unknowns)} are "
                             f"not affine in its inputs {list(knowns)}: a secant is not their derivative")
        return d

    def close(self):
        pass


class FmuSlave(Slave, CouplingSlave):
    """An FMI 2.0 CS FMU (cosim.Slave): fmi2GetDirectionalDerivative where its modelDescription declares
    providesDirectionalDerivative, else the secant of CouplingSlave.directional."""

    def __init__(self, path, name, start: dict | None = None):
        super().__init__(path, name, start=start)
        self.name = name
        self.provides_directional = bool(self.md.coSimulation.providesDirectionalDerivative)

    def directional(self, unknowns, knowns, seed) -> np.ndarray:
        if not self.provides_directional:
            return CouplingSlave.directional(self, unknowns, knowns, seed)
        return np.array(self.fmu.getDirectionalDerivative([self.vr[n] for n in unknowns],
                                                          [self.vr[n] for n in knowns], [float(s) for s in seed]))


class ComponentSlave(CouplingSlave):
    """A pythonfmu component class (fmu_src/, e.g. cart.Cart) run in this process, without its FMU binary: the
    same code its FMU runs, through its registered variables' getters and setters and its do_step."""

    def __init__(self, component_class, name, start: dict | None = None):
        self.name = name
        self.component = component_class(instance_name=name)
        self.variables = {v.name: v for v in self.component.vars.values()}
        if start:
            self.set(start)
        self.component.exit_initialization_mode()

    def _variable(self, name):
        if name not in self.variables:
            raise KeyError(f"{self.name} has no variable {name!r} (it has {', '.join(self.variables)})")
        return self.variables[name]

    def set(self, values: dict):
        for name, value in values.items():
            self._variable(name).setter(float(value))
        self._raise_logged()

    def get(self, names) -> np.ndarray:
        return np.array([self._variable(n).getter() for n in names], float)

    def step(self, t: float, h: float):
        if not self.component.do_step(t, h):
            self._raise_logged()
            raise RuntimeError(f"{self.name} refused the step from t = {t:g} s")

    def _raise_logged(self):
        errors = [m for m in self.component.log_queue if m.status.value >= 3]  # fmi2Error and worse
        self.component.log_queue.clear()
        if errors:
            raise RuntimeError(f"{self.name}: " + "; ".join(m.msg for m in errors))


def cart_component(m_c: float) -> ComponentSlave:
    """The cart of fmu_src/cart.py, in this process."""
    sys.path.insert(0, str(ROOT / "fmu_src"))
    from cart import Cart
    return ComponentSlave(Cart, "cart", start={"mass": m_c})


_NAME = re.compile(r"^(X|U|F|P|V|A|Freact)\[(\d+),([123])\]$|^T\[(\d+)\]$")


class SimulatorSlave(CouplingSlave):
    """A network on linknet_core.Simulator, its variables named as its FMU names them (docs/fmu.md): inputs F[k,i]
    (free mass k), P[k,i], V[k,i], A[k,i] (input-driven anchor k, held as P + V tau + A tau^2/2 from the point where
    they are set); outputs X[k,i], U[k,i], Freact[k,i] (anchored mass k), T[l]. ``directional`` is
    Simulator.interface_linearization's, exact (docs/interface_jacobians.md)."""

    provides_directional = True

    def __init__(self, scene, name="chain", method="dop853", rtol=cc.RTOL):
        self.name = name
        self.scene = ln.load_scene(scene) if isinstance(scene, (str, Path)) else scene
        self.sim = ln.Simulator(self.scene, method=method, rtol=rtol)
        self.driven = [int(k) for k in self.scene.input_driven_indices]
        self.anchored = [int(k) for k in self.scene.fixed_indices]
        self.F = np.zeros((self.scene.K, 3))
        self.motion = {"P": self.scene.X0[self.driven].astype(float), "V": np.zeros((len(self.driven), 3)),
                       "A": np.zeros((len(self.driven), 3))}
        self._out = None  # outputs at the current state and inputs, until either changes

    def _parse(self, name):
        m = _NAME.match(name)
        if not m:
            raise KeyError(f"{self.name} has no variable {name!r} (X, U, F, P, V, A, Freact [k,i] or T[l])")
        if m.group(4):
            link = int(m.group(4)) - 1
            if not 0 <= link < self.scene.L:
                raise KeyError(f"{name}: {self.name} has links 1..{self.scene.L}")
            return "T", link, None
        kind, k, i = m.group(1), int(m.group(2)) - 1, int(m.group(3)) - 1
        if not 0 <= k < self.scene.K:
            raise KeyError(f"{name}: {self.name} has masses 1..{self.scene.K}")
        if kind in ("P", "V", "A"):
            if k not in self.driven:
                raise KeyError(f"{name}: {self.scene.mass_label(k)} is not an input-driven anchor")
            return kind, self.driven.index(k), i
        if kind == "Freact":
            if k not in self.anchored:
                raise KeyError(f"{name}: {self.scene.mass_label(k)} is not anchored")
            return kind, self.anchored.index(k), i
        return kind, k, i

    def _anchors(self):
        return (self.motion["P"], self.motion["V"], self.motion["A"])

    def set(self, values: dict):
        for name, value in values.items():
            kind, row, i = self._parse(name)
            if kind == "F":
                self.F[row, i] = value
            elif kind in ("P", "V", "A"):
                self.motion[kind][row, i] = value
            else:
                raise KeyError(f"{name} is an output of {self.name}, not an input")
        self._out = None

    def get(self, names) -> np.ndarray:
        if self._out is None:
            self._out = self.sim.outputs(self.F, anchors=self._anchors())
        out = []
        for name in names:
            kind, row, i = self._parse(name)
            if kind == "T":
                out.append(self._out["T"][row])
            elif kind in ("P", "V", "A"):
                out.append(self.motion[kind][row, i])
            elif kind == "F":
                out.append(self.F[row, i])
            else:
                out.append(self._out[kind][row, i])
        return np.array(out, float)

    def step(self, t: float, h: float):
        if abs(self.sim.state.t - t) > 1e-9 * max(1.0, abs(t)):
            raise ValueError(f"{self.name} is at t = {self.sim.state.t:g} s, asked to step from {t:g} s")
        self.sim.advance(t + h, self.F, anchors=self._anchors())
        self._out = None

    def directional(self, unknowns, knowns, seed) -> np.ndarray:
        seeds = {"F": np.zeros_like(self.F), **{k: np.zeros_like(v) for k, v in self.motion.items()}}
        for name, s in zip(knowns, seed):
            kind, row, i = self._parse(name)
            if kind not in seeds:
                raise KeyError(f"{name} is an output of {self.name}: seed its inputs (F, P, V, A)")
            seeds[kind][row, i] += s
        lin = self.sim.interface_linearization(self.F, anchors=self._anchors())
        d = lin.directional(dF=seeds["F"], **{f"d{k}": seeds[k] for k in "PVA"})
        out = []
        for name in unknowns:
            kind, row, i = self._parse(name)
            if kind in ("X", "U", "F", "P", "V", "A"):  # states and inputs: no direct feedthrough from an input
                out.append(0.0)
            elif kind == "T":
                out.append(d["T"][row])
            else:
                out.append(d["Freact"][row, i])
        return np.array(out, float)


# ---------------------------------------------------------------------------- the master
def solve_loop(slaves: dict, held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inputs u of the LOOP connections (in its order) that close the loop u = y(u) for the slaves'
    outputs linearised at the held inputs u_0 = ``held``: (I - J) u = y_0 - J u_0, J[i, j] = dy_i/du_j from
    each slave's directional derivative (one seed per loop input). Returns u and J."""
    n = len(LOOP)
    y0 = np.array([slaves[src].get([out])[0] for src, out, _, _ in LOOP])
    J = np.zeros((n, n))
    for j, (_, _, dst, inp) in enumerate(LOOP):
        rows = [i for i, c in enumerate(LOOP) if c[0] == dst]
        J[rows, j] = slaves[dst].directional([LOOP[i][1] for i in rows], [inp], [1.0])
    u = np.linalg.solve(np.eye(n) - J, y0 - J @ held)
    return u, J


def implicit_master(cart: CouplingSlave, chain: CouplingSlave, h: float, t_end: float,
                    sample=cc.SAMPLE) -> dict:
    """The linearly implicit loop (module doc) on two slaves. Returns what cart_chain.master does (x, X every
    `sample` s; a_steps; failed; wall), and m_eff (the chain's effective mass at each step, -J_A) and defect (the
    loop's largest residual after the solve, |Freact(A) - F| in N and |a(F) - A| in m/s2: zero to round-off)."""
    slaves = {"cart": cart, "chain": chain}
    n = cc.chain_model()[0].n
    names = cc._chain_names(n)
    steps = int(round(t_end / h))
    every = int(round(sample / h))
    held = np.array([slaves[dst].get([inp])[0] for _, _, dst, inp in LOOP])
    xs, Xs, a_steps, m_eff, defect = [], [], [], [], 0.0
    failed = None
    start = time.perf_counter()
    try:
        for k in range(steps + 1):
            t = k * h
            for src, out, dst, inp in STATES:
                slaves[dst].set({inp: slaves[src].get([out])[0]})
            held, J = solve_loop(slaves, held)
            for (_, _, dst, inp), value in zip(LOOP, held):
                slaves[dst].set({inp: value})
            y = np.array([slaves[src].get([out])[0] for src, out, _, _ in LOOP])
            defect = max(defect, float(np.max(np.abs(y - held))))
            a = cart.get(["a"])[0]
            a_steps.append(a)
            m_eff.append(-J[FORCE, ACCELERATION])  # -dFreact/dA
            if k % every == 0:
                xs.append(cart.get(["x"])[0])
                Xs.append(chain.get(names).reshape(n, 2))
            if k == steps:
                break
            if not abs(a) < cc.A_BLOWN_UP:
                raise cc.CouplingFailed(t, f"the cart's acceleration is {a:.3g} m/s2")
            try:
                cart.step(t, h)
                chain.step(t, h)
            except Exception as exc:  # an FMU's fmi2Discard / fmi2Error, the library's SolverError
                raise cc.CouplingFailed(t, f"a step was refused ({exc})") from None
    except cc.CouplingFailed as exc:
        failed = exc.t
    wall = time.perf_counter() - start
    cc.close_quietly(cart, chain)
    return dict(x=np.array(xs), X=np.array(Xs), a_steps=np.array(a_steps), m_eff=np.array(m_eff), defect=defect,
                h=h, failed=failed, wall=wall)


def library_slaves(m_c: float) -> tuple[CouplingSlave, CouplingSlave]:
    """The cart (fmu_src/cart.py in this process) and the chain on linknet_core.Simulator."""
    return cart_component(m_c), SimulatorSlave(cc.SCENE)


def run_library(m_c: float, h: float, t_end: float, sample=cc.SAMPLE) -> dict:
    return implicit_master(*library_slaves(m_c), h, t_end, sample)


def fmu_slaves(fmus: dict, m_c: float) -> tuple[CouplingSlave, CouplingSlave]:
    """The cart FMU and the chain FMU (cart_chain.build)."""
    return FmuSlave(fmus["cart"], "cart", start={"mass": m_c}), FmuSlave(fmus["chain"], "chain")


def loop_gain(m_c: float, implicit: bool, dA: float = 1.0) -> float:
    """d a_0 / d A_0 at the release, measured: how a change dA of the hook acceleration held from the step before
    moves the cart's acceleration that the master sets for the next step. The explicit loop (a = Freact(A_0)/m_c):
    -m_eff/m_c, the factor the error is multiplied by each step; the implicit one: 0."""
    cart, chain = library_slaves(m_c)
    slaves = {"cart": cart, "chain": chain}
    out = []
    for A0 in (0.0, dA):
        chain.set({"A[1,1]": A0})
        if implicit:
            out.append(solve_loop(slaves, np.array([0.0, A0]))[0][1])
        else:
            out.append(chain.get(["Freact[1,1]"])[0] / m_c)
    return (out[1] - out[0]) / dA


def sensitivity(m_c: float, t_end: float, eps: float = 1e-4) -> float:
    """How much the monolithic motion itself amplifies an error: the largest distance (cart or chain mass) over
    [0, t_end] between the reference and the reference released with every angle eps rad larger, over eps (m/rad).
    A coupling error made early grows by as much, whatever the master."""
    model, theta0 = cc.chain_model(m_c=m_c)
    t = np.arange(int(round(t_end / cc.SAMPLE)) + 1) * cc.SAMPLE
    runs = [simulate_reference(model, np.r_[0.0, theta0 + d], np.zeros(model.n + 1), t) for d in (0.0, eps)]
    gap = np.maximum(np.abs(runs[0]["x"] - runs[1]["x"]),
                     np.linalg.norm(runs[0]["P"] - runs[1]["P"], axis=2).max(axis=1))
    return float(gap.max() / eps)


# ---------------------------------------------------------------------------- main
def worst_acceleration_error(run: dict, m_c: float, t_end: float) -> float:
    """max |a_n - a_ref(t_n)| over every communication point from t = 0 (the implicit master has no start-up
    error: its first a solves the loop)."""
    ref = cc.reference(m_c, t_end, sample=run["h"])
    a = run["a_steps"]
    return float(np.max(np.abs(a - ref["a"][:len(a)])))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ratios", type=float, nargs="+", default=list(RATIOS), help="m_c / m_chain")
    p.add_argument("--h", type=float, nargs="+", default=[0.008, 0.004, 0.002, 0.001, 0.0005])
    p.add_argument("--t-end", type=float, default=T_END,
                   help="(s) past ~1.8 s the light carts' motion itself amplifies any error tenfold (module doc)")
    p.add_argument("--fmu", action="store_true", help="the cart and chain FMUs instead of the library slaves")
    p.add_argument("--kind", choices=("native", "python"), default="native", help="the chain FMU's kind (--fmu)")
    p.add_argument("--out", default=str(ROOT / "build" / "compositions"))
    a = p.parse_args(argv)
    model, theta0 = cc.chain_model()
    m_chain = float(model.mu[0])
    m_eff0 = model.added_mass(np.r_[0.0, theta0])
    if a.fmu:
        fmus = cc.build(Path(a.out), native=a.kind == "native")
        slaves = lambda m_c: fmu_slaves(fmus, m_c)  # noqa: E731
        explicit = lambda m_c, h, t_end: cc.master(fmus, m_c, h, t_end)  # noqa: E731
        probe = slaves(1.0)
        how = {s.name: "fmi2GetDirectionalDerivative" if s.provides_directional else "secant" for s in probe}
        for s in probe:
            s.close()
        label = f"cart FMU + {a.kind} chain FMU (derivatives: cart {how['cart']}, chain {how['chain']})"
    else:
        slaves = library_slaves
        explicit = cc.library_master
        label = "cart (fmu_src/cart.py in process) + chain on linknet_core.Simulator (interface_linearization)"
    print(f"{label}; chain {m_chain:g} kg, m_eff = {m_eff0:.4g} kg at the release, t_end = {a.t_end:g} s")
    worst = {}
    for r in a.ratios:
        m_c = r * m_chain
        runs = {}

        def run(h):
            runs[h] = implicit_master(*slaves(m_c), h, a.t_end)
            return runs[h]
        cc.convergence(f"implicit master, m_c / m_chain = {r:g}", run, a.h, m_c, a.t_end)
        for h, rr in runs.items():
            worst[r, h] = ("blown up at %.3g s" % rr["failed"] if rr["failed"] is not None
                           else f"{worst_acceleration_error(rr, m_c, a.t_end):.3g}")
        print(f"  loop residual after the solve, |Freact(A) - F| (N) and |a(F) - A| (m/s2): max "
              f"{max(rr['defect'] for rr in runs.values()):.1e};"
              f" m_eff along the run: {min(rr['m_eff'].min() for rr in runs.values()):.3g} .. "
              f"{max(rr['m_eff'].max() for rr in runs.values()):.3g} kg")
        if m_c > m_eff0:  # the explicit loop is stable here: its errors beside these
            cc.convergence(f"explicit loop (cart_chain.py), m_c / m_chain = {r:g}",
                           lambda h: explicit(m_c, h, a.t_end), a.h, m_c, a.t_end)
    rows = []
    for h in a.h:
        row = [f"{h:g}"]
        for r in a.ratios:
            ok, info = cc.stable(explicit, r, h, a.t_end, m_chain)
            row.append("blown up at %.3g s" % info["run"]["failed"] if info["run"]["failed"] is not None
                       else f"{info['growth']:.3g}")
        row += [worst[r, h] for r in a.ratios]
        rows.append(row)
    print("stability: explicit loop's growth max |a_n - a_ref| / |a_0 - a_ref(0)| (stable <= 1) | implicit master's "
          "max |a_n - a_ref(t_n)| from t = 0 (m/s2)")
    cc._table(rows, ["h (s)"] + [f"explicit {r:g}" for r in a.ratios] + [f"implicit {r:g}" for r in a.ratios])
    print("d a_0 / d A_0 at the release (per-step factor on an error in a), measured on the library slaves:")
    cc._table([[f"{r:g}", f"{-m_eff0 / (r * m_chain):.4g}", f"{loop_gain(r * m_chain, False):.4g}",
                f"{loop_gain(r * m_chain, True):.1e}"] for r in a.ratios],
              ["m_c / m_chain", "-m_eff/m_c", "explicit", "implicit"])
    print("the monolithic motion's own amplification of an early error: max distance from the reference over "
          f"[0, {a.t_end:g}] s after releasing every angle 1e-4 rad larger, / 1e-4 rad (m/rad):")
    cc._table([[f"{r:g}", f"{sensitivity(r * m_chain, a.t_end):.3g}"] for r in a.ratios],
              ["m_c / m_chain", "m/rad"])
    return 0


if __name__ == "__main__":
    finish(main())
