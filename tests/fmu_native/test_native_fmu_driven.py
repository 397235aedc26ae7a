"""Driven anchors through the native FMU: inputs P, V, A of an input-driven anchor (held as P + V tau + A tau^2/2),
their FMI input derivatives, outputs Freact and Jreact, against linknet_core's Simulator.advance(anchors=) and
against the physics of an inelastic jump; ModelStructure, fmpy's validation, FMU states and bad input.

The native FMU holds no Python, so these tests drive it in this process through fmpy's FMU2Slave."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from native_fmu_support import ROOT, assert_round_off, built, fmpy_instance

sys.path.insert(0, str(ROOT / "tests"))
import driven_fmu_support as drive  # noqa: E402
import linknet_core as ln  # noqa: E402

WARNING = 1


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("driven_scenes")
    return {name: drive.write_scene(root, name) for name in drive.SCENES}


class Instance:
    """One instance of a built FMU through fmpy, by variable names; log messages collected with their status."""

    def __init__(self, fmu, name="driven"):
        self.fmu, self.log = fmu, []
        self.slave, self.callbacks = fmpy_instance(fmu, name, self.log)

    def vrs(self, names):
        return [self.fmu.vr[n] for n in names]

    def derivatives(self, vrs, orders, values) -> int:
        """fmi2SetRealInputDerivatives; its status (fmpy raises on fmi2Error and above)."""
        from fmpy.fmi2 import fmi2Integer, fmi2Real, fmi2ValueReference
        n = len(vrs)
        return self.slave.fmi2SetRealInputDerivatives(self.slave.component, (fmi2ValueReference * n)(*vrs), n,
                                                      (fmi2Integer * n)(*orders), (fmi2Real * n)(*values))

    def initialize(self, parameters=None, integrator=None):
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        if parameters:
            self.slave.setReal(self.vrs(parameters), list(parameters.values()))
        if integrator:
            self.slave.setString([self.fmu.vr["integrator"]], [integrator])
        self.slave.exitInitializationMode()

    def set_inputs(self, scene, n, motion, derivatives=False):
        """The inputs of communication point n: F, and the anchor's P with V, A as inputs or as P's derivatives."""
        P, V, A = motion
        k = drive.ANCHOR[scene.name]
        names = [f"P[{k},{i}]" for i in (1, 2, 3)]
        values = list(P[n])
        forced = drive.FORCED[scene.name]
        if forced:
            names += [f"F[{forced},{i}]" for i in (1, 2, 3)]
            values += list(drive.BOB2_FORCE)
        if not derivatives:
            names += [f"V[{k},{i}]" for i in (1, 2, 3)] + [f"A[{k},{i}]" for i in (1, 2, 3)]
            values += list(V[n]) + list(A[n])
        self.slave.setReal(self.vrs(names), values)
        if derivatives:
            p = self.vrs([f"P[{k},{i}]" for i in (1, 2, 3)])
            assert self.derivatives(p + p, [1, 1, 1, 2, 2, 2], list(V[n]) + list(A[n])) == 0

    def run(self, scene, names, n_first, n_last, motion, derivatives=False):
        """Rows t, names at points n_first .. n_last, stepping between them."""
        rows = []
        for n in range(n_first, n_last + 1):
            self.set_inputs(scene, n, motion, derivatives)
            rows.append([n * drive.H] + list(self.slave.getReal(self.vrs(names))))
            if n < n_last:
                self.slave.doStep(currentCommunicationPoint=n * drive.H, communicationStepSize=drive.H)
        return np.array(rows)

    def free(self):
        self.slave.freeInstance()


def _run(fmu, scene, names, jump_step=None, derivatives=False, integrator=None, parameters=None):
    inst = Instance(fmu)
    inst.initialize(parameters, integrator)
    k = drive.ANCHOR[scene.name] - 1
    rows = inst.run(scene, names, 0, drive.N_STEPS, drive.anchor_motion(scene.X0[k], jump_step=jump_step),
                    derivatives)
    inst.free()
    return rows


@pytest.mark.parametrize("name,method", [("driven_pendulum", "rattle"), ("driven_chain", "rattle"),
                                         ("driven_chain", "dop853"), ("driven_pendulum", "yoshida4")])
def test_driven_anchor_runs_equal_the_library(name, method, scenes, fmu_root):
    """Every output (X, U, T, Freact, Jreact) at every communication point equals Simulator.advance(anchors=)'s
    run with the same held inputs; the scene-motion anchor of driven_chain is moved by the core itself."""
    fmu = built(fmu_root, scenes[name])
    scene = ln.load_scene(scenes[name])
    names = drive.output_names(fmu.md)
    rows = _run(fmu, scene, names, integrator=method)
    ref = drive.library_outputs(scene, names, method)
    assert_round_off(rows, ref, f"{name} {method}", names)
    k = drive.ANCHOR[name]
    x = [names.index(f"X[{k},{i}]") + 1 for i in (1, 2, 3)]
    assert np.ptp(rows[:, x], axis=0).max() > 1e-3  # the anchor moved
    if name == "driven_chain":
        shaker = [names.index(f"X[8,{i}]") + 1 for i in (1, 3)]
        assert np.ptp(rows[:, shaker], axis=0).min() > 1e-3  # so did the sine-driven one


def test_outputs_read_after_a_step_see_the_held_motion(scenes, fmu_root):
    """A master that reads the outputs after doStep and sets the next inputs after that (fmpy's simulate_fmu) sees
    the anchor where its held quadratic took it, with the tensions of that motion: the library's outputs() with the
    last hold. The anchor's X lands on the next P of the (continuous) input motion."""
    fmu = built(fmu_root, scenes["driven_chain"])
    scene = ln.load_scene(scenes["driven_chain"])
    names = drive.output_names(fmu.md)
    motion = drive.anchor_motion(scene.X0[0])
    inst = Instance(fmu)
    inst.initialize()
    rows = []
    for n in range(drive.N_STEPS):
        inst.set_inputs(scene, n, motion)
        inst.slave.doStep(currentCommunicationPoint=n * drive.H, communicationStepSize=drive.H)
        rows.append([(n + 1) * drive.H] + list(inst.slave.getReal(inst.vrs(names))))
    inst.free()
    rows = np.array(rows)
    assert_round_off(rows, drive.library_outputs(scene, names, read_after=True), "read after the step", names)
    X = rows[:, [names.index(f"X[1,{i}]") + 1 for i in (1, 2, 3)]]
    np.testing.assert_allclose(X, motion[0][1:], rtol=0, atol=1e-12)


def test_changed_mass_with_a_driven_anchor_equals_the_library(scenes, fmu_root):
    """A mass set before initialization rebuilds the model (1/M and the accelerations of B (26)) in C."""
    fmu = built(fmu_root, scenes["driven_pendulum"])
    scene = ln.load_scene(scenes["driven_pendulum"])
    names = drive.output_names(fmu.md)
    rows = _run(fmu, scene, names, parameters={"M[2]": 4.0})
    changed = scene.with_parameters(mass=np.array([np.inf, 4.0]), length=scene.length, gravity=scene.gravity)
    assert_round_off(rows, drive.library_outputs(changed, names), "M[2] = 4", names)
    assert not np.allclose(rows, _run(fmu, scene, names))  # the mass mattered


def test_input_derivatives_give_the_run_of_V_and_A_inputs(scenes, fmu_root):
    fmu = built(fmu_root, scenes["driven_chain"])
    scene = ln.load_scene(scenes["driven_chain"])
    names = drive.output_names(fmu.md)
    assert fmu.md.coSimulation.canInterpolateInputs
    direct = _run(fmu, scene, names)
    assert np.array_equal(_run(fmu, scene, names, derivatives=True), direct)


def test_fmpy_simulate_fmu_with_input_derivatives(scenes, fmu_root):
    """A standard master: fmpy's simulate_fmu with set_input_derivatives=True sets P from a table and its slope as
    order-1 derivatives (and derivatives of the force and A inputs, which the FMU ignores with a warning). The pivot
    moves at constant velocity v from rest: the run equals the library's with anchors (P(t_n), v, 0), the anchor's X
    follows the table and the start is a velocity jump, J = -m (v.e) e."""
    import fmpy
    fmu = built(fmu_root, scenes["driven_pendulum"])
    scene = ln.load_scene(scenes["driven_pendulum"])
    names = drive.output_names(fmu.md)
    v, X0, force = np.array([0.5, 0.0, 0.2]), scene.X0[0], np.array([0.3, 0.0, 0.0])
    # fmpy 0.3.32 sizes its derivative buffer for 9 continuous inputs (simulation.py: (value_type * 9)()): give 9
    columns = [f"P[1,{i}]" for i in (1, 2, 3)] + [f"F[2,{i}]" for i in (1, 2, 3)] + [f"A[1,{i}]" for i in (1, 2, 3)]
    signal = np.array([(t, *(X0 + v * t), *force, 0.0, 0.0, 0.0) for t in (-1.0, 1.0)],
                      dtype=[("time", float)] + [(c, float) for c in columns])
    log = []
    result = fmpy.simulate_fmu(str(fmu.path), stop_time=0.2, output_interval=drive.H, input=signal,
                               set_input_derivatives=True, output=names, logger=lambda *a: log.append(a))
    rows = np.array([[r[n] for n in names] for r in result])[1:]
    sim = ln.Simulator(scene)  # the FMU's default method
    F = np.zeros((2, 3))
    F[1] = force
    ref = []
    for n in range(rows.shape[0]):
        sim.advance(n * drive.H + drive.H, F, anchors=((X0 + v * n * drive.H)[None], v[None], np.zeros((1, 3))))
        out = sim.outputs(F)
        peak, when = sim.tension_peaks()
        ref.append(np.concatenate([out["X"].ravel(), out["U"].ravel(), out["T"], peak, when,
                                   out["Freact"].ravel(), out["impulse"].ravel(), [out["error_estimate"]]]))
    assert names == [f"{q}[{k},{i}]" for q in "XU" for k in (1, 2) for i in (1, 2, 3)] + \
        ["T[1]", "T_peak[1]", "T_peak_time[1]"] + \
        [f"{q}[1,{i}]" for q in ("Freact", "Jreact") for i in (1, 2, 3)] + ["error_estimate"]
    ref = np.array(ref)
    scale = np.maximum(np.abs(ref).max(axis=0), 1e-300)
    scale[-1] = max(scale[-1], np.abs(ref[:, :6]).max())  # a gap of positions: their round-off
    assert (np.abs(rows - ref) / scale).max() < 1e-9
    np.testing.assert_allclose(rows[:, :3], X0 + v * drive.H * np.arange(1, rows.shape[0] + 1)[:, None], atol=1e-12)
    e = (scene.X0[1] - X0) / np.linalg.norm(scene.X0[1] - X0)
    np.testing.assert_allclose(rows[0, -4:-1], -1.5 * float(v @ e) * e, rtol=1e-9)
    assert any(status == WARNING and b"is held constant" in message for _, _, status, _, message in log)


def test_a_velocity_jump_is_an_inelastic_impulse(scenes, fmu_root):
    """The anchor's velocity jumps by dv at the start of a step: the link keeps its length, so the bob's velocity
    along the link jumps with the anchor's, m (dv.e) e, and the link gives the anchor the opposite impulse,
    J = -m (dv.e) e (e from the anchor to the bob); the library reports the same."""
    fmu = built(fmu_root, scenes["driven_pendulum"])
    scene = ln.load_scene(scenes["driven_pendulum"])
    names = drive.output_names(fmu.md)
    jump = 10
    rows = _run(fmu, scene, names, jump_step=jump)
    assert_round_off(rows, drive.library_outputs(scene, names, jump_step=jump), "velocity jump", names)
    col = {n: i + 1 for i, n in enumerate(names)}
    J = rows[:, [col[f"Jreact[1,{i}]"] for i in (1, 2, 3)]]
    # no jump before (the quadratics meet to round-off: impulses of ~1e-17 N s) and after the step that starts with it
    assert np.abs(J[:jump + 1]).max() < 1e-12 and np.abs(J[jump + 2:]).max() < 1e-12
    X = rows[jump, [col[f"X[{k},{i}]"] for k in (1, 2) for i in (1, 2, 3)]].reshape(2, 3)
    e = (X[1] - X[0]) / np.linalg.norm(X[1] - X[0])
    expected = -1.5 * float(drive.JUMP @ e) * e
    np.testing.assert_allclose(J[jump + 1], expected, rtol=1e-9, atol=1e-12)


def test_model_structure_is_the_coupled_groups_of_links(scenes, fmu_root):
    """Freact and T depend directly on F and on the P, V, A of the anchors of their group of links only; X, U
    and Jreact on no input."""
    fmu = built(fmu_root, scenes["driven_chain"])
    md = fmu.md
    deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}

    def inputs(*masses, anchor=False):
        out = [f"F[{k},{i}]" for k in masses for i in (1, 2, 3)]
        if anchor:
            out += [f"{q}[1,{i}]" for q in "PVA" for i in (1, 2, 3)]
        return sorted(out)

    chain, fixed_pendulum, shaken = inputs(2, 3, 4, 5, anchor=True), inputs(7), inputs(9)
    expected = {f"T[{l}]": chain for l in (1, 2, 3, 4)}
    expected.update({"T[5]": fixed_pendulum, "T[6]": shaken})
    expected.update({f"Freact[{k},{i}]": d for k, d in ((1, chain), (6, fixed_pendulum), (8, shaken))
                     for i in (1, 2, 3)})
    expected.update({f"{q}[{k},{i}]": [] for q in "XU" for k in range(1, 10) for i in (1, 2, 3)})
    expected.update({f"Jreact[{k},{i}]": [] for k in (1, 8) for i in (1, 2, 3)})
    expected["error_estimate"] = []
    expected.update({f"{q}[{l}]": [] for q in ("T_peak", "T_peak_time") for l in range(1, 7)})  # over the last step
    assert deps == expected
    inputs_declared = [v.name for v in md.modelVariables if v.causality == "input"]
    assert inputs_declared[-9:] == [f"{q}[1,{i}]" for q in "PVA" for i in (1, 2, 3)]  # not for the sine anchor
    start = {v.name: float(v.start) for v in md.modelVariables if v.causality == "input"}
    assert [start[f"P[1,{i}]"] for i in (1, 2, 3)] == [0.0, 0.0, 0.0]


def test_declared_dependencies_are_the_outputs_each_input_moves(scenes, fmu_root):
    """ModelStructure checked against the FMU's own answers: mid-run, each input in turn is changed and every output
    read again; the outputs that change are exactly those declared to depend on it (the scene's geometry is generic:
    no link perpendicular to another or to an axis, where a dependency could vanish)."""
    fmu = built(fmu_root, scenes["driven_chain"])
    scene = ln.load_scene(scenes["driven_chain"])
    names = drive.output_names(fmu.md)
    declared = {u.variable.name: {d.name for d in u.dependencies} for u in fmu.md.outputs}
    inputs = [v.name for v in fmu.md.modelVariables if v.causality == "input"]
    inst = Instance(fmu)
    inst.initialize()
    motion = drive.anchor_motion(scene.X0[0], jump_step=3)
    inst.run(scene, names, 0, 6, motion)  # a moving, tilted state with a recent jump
    base = dict(zip(inputs, inst.slave.getReal(inst.vrs(inputs))))
    before = np.array(inst.slave.getReal(inst.vrs(names)))
    for name in inputs:
        inst.slave.setReal(inst.vrs([name]), [base[name] + 0.25])
        moved = {n for n, a, b in zip(names, before, inst.slave.getReal(inst.vrs(names))) if a != b}
        assert moved == {n for n in names if name in declared[n]}, name
        inst.slave.setReal(inst.vrs([name]), [base[name]])
    inst.free()


@pytest.mark.parametrize("name", ["driven_pendulum", "driven_chain"])
def test_fmpy_validation_is_clean(name, scenes, fmu_root):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(built(fmu_root, scenes[name]).path)) == []


def test_states_with_driven_anchors_replay_bit_for_bit(scenes, fmu_root):
    """A state taken mid-run carries the held anchor motion, its clock and the last impulse: restoring it (and
    deserializing it into a fresh instance) replays the rest of a run with a velocity jump bit for bit, and a hold
    set but not yet stepped with goes on after a restore."""
    fmu = built(fmu_root, scenes["driven_chain"])
    scene = ln.load_scene(scenes["driven_chain"])
    names = drive.output_names(fmu.md)
    motion = drive.anchor_motion(scene.X0[0], jump_step=8)
    inst = Instance(fmu)
    inst.initialize()
    inst.run(scene, names, 0, 8, motion)
    inst.slave.doStep(currentCommunicationPoint=8 * drive.H, communicationStepSize=drive.H)  # the jump's step
    state = inst.slave.getFMUstate()
    first = inst.run(scene, names, 9, 20, motion)
    assert np.abs(first[0, [names.index(f"Jreact[1,{i}]") + 1 for i in (1, 2, 3)]]).max() > 0  # carried over
    inst.slave.setFMUstate(state)
    assert np.array_equal(inst.run(scene, names, 9, 20, motion), first)
    data = inst.slave.serializeFMUstate(state)
    inst.slave.freeFMUstate(state)
    fresh = Instance(fmu, "fresh")
    fresh.initialize()
    fresh.slave.setFMUstate(fresh.slave.deSerializeFMUstate(data))
    assert np.array_equal(fresh.run(scene, names, 9, 20, motion), first)

    # at point 20 the inputs are set and not yet stepped with: a state taken now carries that hold, which goes on
    # over steps with no new inputs (the anchor keeps to its quadratic)
    def coast(instance):
        rows = []
        for n in (20, 21, 22):
            instance.slave.doStep(currentCommunicationPoint=n * drive.H, communicationStepSize=drive.H)
            rows.append(instance.slave.getReal(instance.vrs(names)))
        return np.array(rows)
    held = fresh.slave.getFMUstate()
    coasted = coast(fresh)
    fresh.slave.setFMUstate(held)
    assert np.array_equal(coast(fresh), coasted)
    inst.slave.setFMUstate(inst.slave.deSerializeFMUstate(fresh.slave.serializeFMUstate(held)))
    assert np.array_equal(coast(inst), coasted)
    P, V, A = (q[20] for q in motion)
    tau = drive.H * np.arange(1, 4)[:, None]
    X = coasted[:, [names.index(f"X[1,{i}]") for i in (1, 2, 3)]]
    np.testing.assert_allclose(X, P + V * tau + A * tau ** 2 / 2, rtol=0, atol=1e-12)
    inst.free()
    fresh.free()


def test_bad_anchor_inputs_are_refused_and_the_fmu_goes_on(scenes, fmu_root):
    from fmpy.fmi1 import FMICallException
    fmu = built(fmu_root, scenes["driven_pendulum"])
    scene = ln.load_scene(scenes["driven_pendulum"])
    names = drive.output_names(fmu.md)
    inst = Instance(fmu)
    inst.initialize()
    vr = fmu.vr
    cases = [
        (lambda: inst.slave.setReal([vr["P[1,2]"]], [float("nan")]), "P[1,2] = nan is not a finite position"),
        (lambda: inst.slave.setReal([vr["V[1,1]"], vr["A[1,3]"]], [0.0, float("inf")]),
         "A[1,3] = inf is not a finite acceleration"),
        (lambda: inst.slave.setReal([vr["V[1,1]"]], [1e200]), "V[1,1] = 1e+200: an anchor's velocity beyond"),
        (lambda: inst.slave.setReal([vr["Jreact[1,1]"]], [1.0]), "Jreact[1,1] is an output"),
        (lambda: inst.derivatives([vr["P[1,1]"]], [3], [1.0]), "order 3 of P[1,1]"),
        (lambda: inst.derivatives([vr["P[1,1]"]], [0], [1.0]), "order 0 of P[1,1]"),
        (lambda: inst.derivatives([vr["X[2,1]"]], [1], [1.0]), "X[2,1] is an output"),
        (lambda: inst.derivatives([vr["M[2]"]], [1], [1.0]), "M[2] is a parameter"),
        (lambda: inst.derivatives([9999], [1], [1.0]), "value reference 9999"),
        (lambda: inst.derivatives([vr["P[1,1]"], vr["P[1,2]"]], [1, 2], [1.0, float("nan")]),
         "order 2 of P[1,2] = nan is not a finite acceleration"),
    ]
    for call, words in cases:
        inst.log.clear()
        with pytest.raises(FMICallException):
            call()
        assert any(status == 3 and words in message for status, message in inst.log), (words, inst.log)
    # a derivative of a force input: held constant, so ignored with a warning (a master sending derivatives of all
    # its inputs keeps working), and nothing else set by the call is lost
    inst.log.clear()
    status = inst.derivatives([vr["F[2,1]"], vr["P[1,1]"]], [1, 1], [5.0, 0.25])
    assert status == WARNING
    assert any(s == WARNING and "F[2,1] is held constant" in m for s, m in inst.log), inst.log
    assert inst.slave.getReal([vr["V[1,1]"]]) == [0.25]
    # nothing refused was set: the run goes on as the library's
    rows = inst.run(scene, names, 0, 5, drive.anchor_motion(scene.X0[0]))
    assert_round_off(rows, drive.library_outputs(scene, names, n_steps=5), "after refusals", names)
    inst.free()
