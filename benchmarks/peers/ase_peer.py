"""ASE peer: Atoms with FixBondLengths (SHAKE positions + RATTLE momenta, iterated link by link in Python)
and ase.md.verlet.VelocityVerlet, a gravity Calculator.

Units: ASE works in Angstrom, amu, eV and its own time unit sqrt(amu A^2/eV); reading metres as Angstrom,
kilograms as amu and seconds as that time unit keeps every equation unchanged, so dt is passed as is.

What differs: anchored masses get mass 1e20 and no force (FixAtoms does not compose with FixBondLengths'
mass-weighted corrections); FixBondLengths' iteration tolerance is set to 1e-13. The link-by-link loop is
Python, so it is only run on small scenes (the driver stops a sweep once a run exceeds its time budget).
"""
from __future__ import annotations

import numpy as np

from .base import Method, RunResult, Timer, Unsupported, n_steps

ANCHOR_MASS = 1e20


class ASEVelocityVerlet(Method):
    name = "ase-rattle-verlet"
    knob = "dt"
    order = 2

    MAX_LINKS = 24

    def check_scene(self, spec):
        if spec.L > self.MAX_LINKS:
            raise Unsupported(f"ase: not run above {self.MAX_LINKS} links: FixBondLengths iterates link by link in "
                              "Python (~1 ms per step for 10 links, and it fails to converge on chain_10)")

    def available(self):
        try:
            import ase  # noqa: F401
            return True, ""
        except ImportError as e:
            return False, f"ase not installed ({e})"

    def run(self, spec, t_end, dt):
        from ase import Atoms
        from ase.calculators.calculator import Calculator, all_changes
        from ase.constraints import FixBondLengths
        from ase.md.verlet import VelocityVerlet

        n, dt = n_steps(t_end, dt)
        free = spec.free
        mass = np.where(spec.fixed, ANCHOR_MASS, np.where(spec.fixed, 1.0, spec.mass))
        force = np.zeros((spec.K, 3))
        force[free] = spec.mass[free, None] * spec.gravity[None, :]
        g = spec.gravity

        class Gravity(Calculator):
            implemented_properties = ["energy", "forces"]

            def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
                Calculator.calculate(self, atoms, properties, system_changes)
                x = self.atoms.positions
                self.results["energy"] = float(-np.sum(spec.mass[free] * (x[free] @ g)))
                self.results["forces"] = force.copy()

        with Timer() as setup:
            atoms = Atoms(numbers=[1] * spec.K, positions=spec.X0.copy(), masses=mass, pbc=False)
            atoms.set_velocities(spec.U0.copy())
            atoms.set_constraint(FixBondLengths(np.stack([spec.k1, spec.k2], axis=1), tolerance=1e-13,
                                                bondlengths=spec.length.copy()))
            atoms.calc = Gravity()
            dyn = VelocityVerlet(atoms, timestep=dt)
        with Timer() as tm:
            dyn.run(n)
        X = atoms.get_positions()
        U = atoms.get_velocities()
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n)
