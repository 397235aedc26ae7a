"""Exudyn peer: NodePoint + MassPoint bodies, DistanceConstraint between MarkerBodyPosition markers, anchored
masses as markers on ObjectGround at their position, gravity as LoadMassProportional; implicit
generalized-alpha (index-3 constraints, Newton on the full system) with a fixed step.

What differs: generalized-alpha is second order and, with spectral radius < 1, numerically dissipative. We use
Exudyn's default spectral radius 0.9: with 1.0 (no numerical damping) the index-3 Newton iteration fails on
the whipping chain_10 at every step size tried (1e-2 .. 1e-4 s) and every Newton tolerance (1e-14 .. 1e-6),
a known weakness of undamped index-3 generalized-alpha. Newton runs to 1e-12 (1e-14 is unreachable on the
spinning tetrahedron) so the step size is the only accuracy knob. Redundant links (a state of self-stress)
make the constraint Jacobian rank-deficient: Exudyn's default dense solver, ignoreSingularJacobian set, then stops
at the first step ("System Jacobian seems to be singular", or a Newton diverging), so on such scenes the Eigen
dense solver with ignoreSingularJacobian is used, Exudyn's own advice for redundant constraints.
"""
from __future__ import annotations

import numpy as np

from ..index1 import Index1System
from .base import Method, RunResult, Timer, n_steps


class ExudynGenAlpha(Method):
    knob = "dt"
    order = 2

    def __init__(self, spectral_radius: float = 0.9, newton_tol: float = 1e-12):
        self.newton_tol = newton_tol
        self.rho = spectral_radius
        self.name = "exudyn-genalpha"


    def available(self):
        try:
            import exudyn  # noqa: F401
            return True, ""
        except ImportError as e:
            return False, f"exudyn not installed ({e})"

    def run(self, spec, t_end, dt):
        import exudyn as exu
        import exudyn.itemInterface as ei
        n, dt = n_steps(t_end, dt)
        with Timer() as setup:
            SC = exu.SystemContainer()
            mbs = SC.AddSystem()
            markers, nodes = [], {}
            for k in range(spec.K):
                if spec.fixed[k]:
                    ground = mbs.AddObject(ei.ObjectGround(referencePosition=spec.X0[k].tolist()))
                    markers.append(mbs.AddMarker(ei.MarkerBodyPosition(bodyNumber=ground, localPosition=[0, 0, 0])))
                    continue
                node = mbs.AddNode(ei.NodePoint(referenceCoordinates=spec.X0[k].tolist(),
                                                initialCoordinates=[0.0, 0.0, 0.0],
                                                initialVelocities=spec.U0[k].tolist()))
                body = mbs.AddObject(ei.MassPoint(physicsMass=float(spec.mass[k]), nodeNumber=node))
                markers.append(mbs.AddMarker(ei.MarkerBodyPosition(bodyNumber=body, localPosition=[0, 0, 0])))
                mmass = mbs.AddMarker(ei.MarkerBodyMass(bodyNumber=body))
                mbs.AddLoad(ei.LoadMassProportional(markerNumber=mmass, loadVector=spec.gravity.tolist()))
                nodes[k] = node
            for a, b, r in zip(spec.k1, spec.k2, spec.length):
                mbs.AddObject(ei.DistanceConstraint(markerNumbers=[markers[a], markers[b]], distance=float(r)))
            mbs.Assemble()
            ss = exu.SimulationSettings()
            ti = ss.timeIntegration
            ti.numberOfSteps = n
            ti.endTime = t_end
            ti.verboseMode = 0
            ti.newton.relativeTolerance = self.newton_tol
            ti.newton.absoluteTolerance = self.newton_tol
            ti.newton.useModifiedNewton = False
            ti.newton.maxIterations = 50
            ti.generalizedAlpha.spectralRadius = self.rho
            ti.generalizedAlpha.computeInitialAccelerations = True
            ti.adaptiveStep = False
            ti.automaticStepSize = False
            ss.solutionSettings.writeSolutionToFile = False
            ss.solutionSettings.writeInitialValues = False
            ss.linearSolver.ignoreSingularJacobian = True
            if Index1System(spec).redundant:
                ss.linearSolver.solverType = exu.LinearSolverType.EigenDense
            elif 3 * spec.K > 300:   # Exudyn's own advice above 1000 unknowns; sparse LU pays from a few hundred
                ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        with Timer() as tm:
            ok = mbs.SolveDynamic(ss) if hasattr(mbs, "SolveDynamic") else exu.SolveDynamic(mbs, ss)
        if ok is False:
            raise RuntimeError("exudyn SolveDynamic reported failure")
        X = spec.X0.copy()
        U = np.zeros_like(spec.U0)
        for k, node in nodes.items():
            X[k] = mbs.GetNodeOutput(node, exu.OutputVariableType.Position)
            U[k] = mbs.GetNodeOutput(node, exu.OutputVariableType.Velocity)
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n)
