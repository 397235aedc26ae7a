"""MoorDyn peer on a scene with a ground: the lines of benchmarks.peers.moordyn_peer over MoorDyn's seabed.

MoorDyn's seabed is a penalty, not a constraint (MoorDyn-C, Line::getStateDeriv): a line node below the seabed
z = -WtrDpth by a depth p gets the vertical force (kb p - cb dz/dt) d l_node, with d the line's diameter and l_node
half the unstretched length of the node's segments, and, where its seabed friction is on, a horizontal force
against the node's horizontal velocity v of min(mu FricDamp |v|, mu |F_z|) (a saturated damper: Coulomb's law in
the limit FricDamp -> infinity). The peer's lines have one segment each and end at the points that carry the
scene's masses, so a point of mass m_k gets the contact stiffness k_k = kb d L_k / 2 and damping c_k = cb d L_k / 2,
L_k the summed lengths of its lines (MoorDyn's points themselves have no seabed contact).

One knob ties the seabed to the line: for each stiffness EA, kb = EA / (d R^2) (R the shortest line) makes the
contact stiffness of a point between two lines of length R, kb d R, equal to a line's axial stiffness EA / R, so
that one sweep over EA stiffens both. The contact's damping makes every point at least critically damped (cb from
the point with the smallest ratio): an overdamped spring-dashpot that a mass enters does not let it go again, the
limit of linknet's inelastic contact (restitution 0) as kb grows; a rebounding contact would tend to a restitution
exp(-pi zeta / sqrt(1 - zeta^2)) set by the ratio zeta alone, whatever the stiffness. (Its dashpot also pulls a
mass that leaves the seabed, kb p + cb dp/dt < 0 on the way out: no scene here leaves it.) FricDamp makes the
friction's viscous regime as fast as the contact's damping (FricDamp = the least c_k), so that it too stiffens with
EA: a node slides at the Coulomb force down to the speed N / FricDamp and creeps to rest from there.

What this peer's error is made of (docs/benchmarks/rope_peer.md): a mass at rest on the seabed sinks m g / k_k
into it (~1/EA); a landing lasts ~ pi sqrt(m / k_k) instead of an instant; a mass lying on it at the start sits on
its surface and sinks to m g / k_k, and while it sinks the friction, mu times the contact force, is short of
mu m g: a mass sliding from there runs mu m g / k_k ahead (the sink's own integral), ~1/EA.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .base import Unsupported
from .moordyn_peer import DEPTH, DIAMETER, MoorDynLine

CONTACT_STABILITY = 2.0   # dtM <= 2 / lambda, lambda the fastest rate of a contact (RK4: stable to 2.78 on a decay)


class MoorDynSeabedLine(MoorDynLine):
    """MoorDyn's undamped one-segment lines (MoorDynLine) over its seabed, the seabed stiffened with EA."""

    def __init__(self, EA: float, scheme: str = "RK4", damping: float = 0.0):
        super().__init__(EA, scheme, damping)
        self.name = self.name.replace("moordyn-", "moordyn-seabed-", 1)

    # ------------------------------------------------------------------ the scene
    def check_scene(self, spec):
        if spec.ground is None:
            raise Unsupported("no ground: the seabed peer is for scenes with one (MoorDynLine runs the others)")
        super().check_scene(replace(spec, ground=None))
        ground = spec.ground
        normal = np.asarray(ground.get("normal", (0.0, 0.0, 1.0)), float)
        normal = normal / np.linalg.norm(normal)
        if abs(normal[2] - 1.0) > 1e-12:
            raise Unsupported(f"ground normal {normal.tolist()}: MoorDyn's seabed is level, its normal +z")
        if float(ground.get("restitution", 0.0)) != 0.0:
            raise Unsupported(f"ground restitution {ground['restitution']:g}: the seabed here is overdamped, the limit "
                              "of an inelastic contact (restitution 0); a rebounding penalty contact keeps a "
                              "restitution set by its damping ratio, not by the scene")
        below = np.flatnonzero(spec.free & (spec.X0[:, 2] < self.seabed_z(spec) - 1e-12))
        if below.size:
            raise Unsupported(f"mass {below[0] + 1} starts below the ground: MoorDyn refuses a point below its seabed")

    @staticmethod
    def seabed_z(spec) -> float:
        return float(np.asarray(spec.ground["point"], float)[2])

    # ------------------------------------------------------------------ the seabed's parameters
    def line_length_at(self, spec) -> np.ndarray:
        """L_k: the summed unstretched lengths of the lines at each mass."""
        L = np.zeros(spec.K)
        np.add.at(L, spec.k1, spec.length)
        np.add.at(L, spec.k2, spec.length)
        return L

    def seabed(self, spec) -> dict:
        """kb [Pa/m], cb [Pa s/m], mu, FricDamp [N s/m] and the free masses' contact stiffness and damping."""
        free = spec.free
        m, half = spec.mass[free], 0.5 * DIAMETER * self.line_length_at(spec)[free]   # d L_k / 2
        kb = self.EA / (DIAMETER * float(spec.length.min()) ** 2)
        cb = float(np.max(2.0 * np.sqrt(kb * m / half)))          # zeta >= 1 at every point
        k, c = kb * half, cb * half
        mu = float(spec.ground.get("friction", 0.0))
        return {"kb": kb, "cb": cb, "mu": mu, "FricDamp": float(c.min()), "k": k, "c": c, "m": m}

    def knobs(self, spec, quick: bool) -> list[float]:
        """From the stricter of the line's stability limit and the seabed's: a contact's fastest rate
        (c + sqrt(c^2 - 4 k m)) / (2 m), and the friction's viscous rate mu FricDamp / m."""
        s = self.seabed(spec)
        fastest = np.max((s["c"] + np.sqrt(np.maximum(s["c"] ** 2 - 4 * s["k"] * s["m"], 0.0))) / (2 * s["m"]))
        fastest = max(fastest, float(np.max(s["mu"] * s["FricDamp"] / s["m"])))
        top = min(super().knobs(spec, quick=True)[0], CONTACT_STABILITY / fastest)
        return [top / 2 ** i for i in range(3 if quick else 16)]

    def input_file(self, spec, X0, dt) -> str:
        """MoorDynLine's input with the seabed at the ground's height and its contact and friction options."""
        s = self.seabed(spec)
        text = super().input_file(spec, X0, dt)
        far = f"{DEPTH!r} WtrDpth"
        if text.count(far) != 1:
            raise RuntimeError("MoorDynLine's input file no longer holds one water depth option to replace")
        near = "\n".join([f"{-self.seabed_z(spec)!r} WtrDpth", f"{s['kb']!r} kBot", f"{s['cb']!r} cBot",
                          f"{s['mu']!r} FrictionCoefficient", f"{s['FricDamp']!r} FricDamp",
                          "1.0 StatDynFricScale"])
        return text.replace(far, near)
