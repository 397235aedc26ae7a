"""Structure specialisation, chosen once per scene: skip what a scene doesn't need.

Two classes of scenes pay the full point-mass machinery of (9), (25)-(26) for nothing:

* **static**: the free masses admit no motion at all, rank G = 3 K_free at the initial state (0 degrees of
  freedom in ``linknet analyze``). Infinitesimal rigidity implies rigidity, so the positions stay X0 and
  the only velocity satisfying (12) is U = 0. ``advance`` moves t only. The tensions are the
  minimum-norm solution of the static balance C^T T + F = 0 ((9) with dU/dt = 0), which is what (25)-(26)
  give at U = 0: A T = B reads C M^-1 (C^T T + F) = 0 there, and C M^-1 has full column rank.

* **free rigid bodies**: every connected component of the link graph is free (no anchored mass), rigid
  (rank G_c = 3 n_c - 6: no internal mechanism) and has >= 3 non-collinear masses (a full inertia
  tensor). Each component moves as one rigid body (the native core's engine_rigid.c), driven by the
  resultant and moment of the external forces F_k of (9); springs, dampers, drag and inputs between or on
  masses are allowed. Anchored masses joined by no link (spring attachment points) are allowed too.
  Fixed-step methods: rattle is the base step kick-drift-rotate-kick (free rotation exact for spherical and
  symmetric tops, DLM splitting otherwise), the compositions compose it with their step fractions. Adaptive
  methods (dopri5, dop853) integrate the Newton-Euler equations of the body state with their own embedded
  pair and the step-size controller of the point-mass path, the error measured on the masses' positions and
  velocities; they take their (rtol, atol) from :func:`choose_specialisation` (``tolerances=``). The
  tensions at an output are those of (25)-(26) at the state.

This module decides which one applies (and why not) and computes the body geometry once (principal axes,
body-frame offsets, the fit of body states to a mass state); linknet_core.native.rigid builds the native
model from it. Everything else takes the point-mass path, with the reason reported.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from linknet_core.dynamics.equations import Dynamics
from linknet_core.integrators import METHODS
from linknet_core.scene.description import Scene
from linknet_core.structure.bodies import TOP_NAMES, BodyLayout, _principal_moments, _top_kinds, free_rigid_bodies
from linknet_core.structure.topology import analyse, kept_per_scene

STATIC, RIGID, NONE = "static", "rigid", "none"


@dataclass
class Specialisation:
    """The path a scene takes, chosen once at construction, with what it means or why there is none."""

    kind: str  # 'static' | 'rigid' | 'none'
    reason: str  # 'none': why not; otherwise a description
    bodies: "BodyLayout | None" = None
    notes: list = field(default_factory=list)
    tolerances: "tuple[float, float] | None" = None  # (rtol, atol) of an adaptive method's rigid-body path

    def text(self) -> str:
        if self.kind == STATIC:
            return f"static (0 dof): {self.reason}"
        if self.kind == RIGID:
            return f"free rigid bodies: {self.bodies.count} ({self.reason})"
        return f"none: {self.reason}"


def choose_specialisation(scene: Scene, dyn: Dynamics, method: str | None = None, enabled: bool = True,
                          tolerances: tuple | None = None) -> Specialisation:
    """The specialisation of ``scene`` for ``method`` (None: report what each kind of method gets).

    ``tolerances``: (rtol, atol) of an adaptive method, which its rigid-body path takes over; without them an
    adaptive method keeps the point-mass path.
    """
    if not enabled:
        return Specialisation(NONE, "specialise=False, or the numpy reference backend: the point-mass path")
    if scene.driven.any():
        n = int(scene.driven.sum())
        return Specialisation(NONE, f"{_count(n, 'driven anchor', 'driven anchors')}: their motion enters (11), (12) "
                                    "and (26) on the point-mass path (nothing stands still, no body is free)")
    st = dyn.structure
    n_free = int(scene.free_indices.size)
    if scene.L and st.rank_exact and st.rank_G == 3 * n_free:
        return Specialisation(STATIC, f"the {n_free} free masses cannot move (rank G = 3 K_free = {3 * n_free}): "
                                      "X = X0, U = 0, advance moves t only; tensions the minimum-norm solution of "
                                      "C^T T + F = 0, i.e. of (25)-(26) at U = 0")
    if st is analyse(scene):  # the scene's own structure: its body layout is kept with the scene
        bodies, why = kept_per_scene(scene, "free rigid bodies", lambda s: free_rigid_bodies(s, dyn))
    else:
        bodies, why = free_rigid_bodies(scene, dyn)
    if bodies is None:
        if not scene.L:
            return Specialisation(NONE, "no links")
        dof = 3 * n_free - st.rank_G
        return Specialisation(NONE, f"not static ({dof} degrees of freedom) and not free rigid bodies: {why}")
    adaptive = method is not None and METHODS[method].adaptive
    if adaptive:
        if tolerances is None or tolerances[0] is None:
            counted = _count(bodies.count, "free rigid body", "free rigid bodies")
            return Specialisation(NONE, f"{counted}, but no tolerances were handed over for the adaptive method "
                                        f"{method}'s rigid-body path (choose_specialisation(..., tolerances=)): "
                                        "it keeps the point-mass path")
        tolerances = (float(tolerances[0]), float(tolerances[1] if tolerances[1] is not None else tolerances[0]))
    else:
        tolerances = None
    _, _, moments, _ = _principal_moments(scene, scene.X0, bodies.body_of, bodies.count)
    kinds = _top_kinds(moments)
    counts = np.bincount(kinds, minlength=3)
    described = ", ".join(_count(n, TOP_NAMES[i], TOP_NAMES[i] + "s") for i, n in enumerate(counts) if n)
    fixed_step = ("kick, drift, free rotation (exact for spherical and symmetric tops, DLM splitting otherwise), "
                  "kick")
    embedded = ("Newton-Euler equations (Euler's equations for Pi, quaternion kinematics) by the method's embedded "
                "Runge-Kutta pair, error control on the masses' positions and velocities, quaternion renormalised "
                "after every step")
    how = "c, v, quaternion and body angular momentum per body; "
    if method is None:
        adaptive_names = "/".join(sorted(name for name, cls in METHODS.items() if cls.adaptive))
        how += f"fixed-step methods: {fixed_step}; adaptive methods ({adaptive_names}): {embedded}"
    elif adaptive:
        how += f"{embedded} (rtol {tolerances[0]:g}, atol {tolerances[1]:g})"
    else:
        how += fixed_step
    return Specialisation(RIGID, f"{described}; {how}", bodies, tolerances=tolerances)


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"
