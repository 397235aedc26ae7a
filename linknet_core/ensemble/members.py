"""What a Dask worker does: run members, one ``ln.simulate`` run or one FMU run through fmpy each.

A study reaches the workers once, as a worker plugin (:class:`StudyPayload`): the scene, the settings and
the FMU's bytes, if any. Dask gives a plugin to every worker of the cluster, including workers that start
later (a nanny restarting a killed one), so tasks carry only member indices and values, and nothing a task
needs can be lost with a worker. Each task runs a batch of consecutive members into one numpy array per output
(member first), filled in place; a member that fails is recorded with its error (its rows stay NaN) and the
batch goes on. Where the worker sees the study's shard folder, it writes the batch there as a shard
(shards.py) and returns the quantities of interest only; otherwise it returns the trajectories too.

A library member is one ``ln.simulate`` call, the very call a serial loop over the members makes: its outputs
and its error estimate are bit-identical to that loop's, sampled in the native core (not output by output from
Python), with the same companion run.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import tempfile
import threading
import time
import warnings
import zipfile
from dataclasses import dataclass

import numpy as np
from distributed import WorkerPlugin, get_worker

from linknet_core.accuracy import AccuracyWarning
from linknet_core.errors import LinknetError, SceneError
from linknet_core.integrators import METHODS
from linknet_core.scene import Scene
from linknet_core.simulator import simulate
from linknet_core.ensemble.parameters import Parameter, member_forces, member_scene
from linknet_core.ensemble.shards import sees_folder, write_shard
from linknet_core.output import WriteError

OUTPUTS = ("X", "U", "T", "Freact")  # what a study can keep per member and time: its trajectories


@dataclass(frozen=True)
class StudySpec:
    """Everything a worker needs to run any member of one study."""

    study_id: str
    scene: dict  # the base scene, Scene.to_dict() form
    parameters: tuple[Parameter, ...]
    times: np.ndarray  # output times, s; times[0] = 0
    method: str | None  # None: the FMU's own integrator (library studies always name one)
    dt: float | None
    rtol: float | None
    atol: float | None
    project_initial: bool | None
    outputs: tuple[str, ...]
    tip: int  # 0-based mass whose final position is a quantity of interest
    fmu: bytes | None = None
    shards: str | None = None  # the study's shard folder (absolute), where workers that see it write trajectories

    def solver(self, setting: dict) -> tuple[str | None, float | None, float | None]:
        """(method, dt, rtol) of a member: its own integrator, step, tolerance if varied, else the study's.
        dt is None for adaptive methods and rtol None for fixed-step ones, as ``Simulator`` wants."""
        method = setting.get("integrator", self.method)
        dt, rtol = setting.get("step", self.dt), setting.get("tolerance", self.rtol)
        if method is None:
            return None, dt, rtol
        return (method, None, rtol) if METHODS[method].adaptive else (method, dt, None)


def output_values(scene: Scene, outputs, n_times: int) -> int:
    """How many numbers one member keeps of ``outputs`` (X, U, T, Freact) over ``n_times`` output times."""
    per_time = {"X": 3 * scene.K, "U": 3 * scene.K, "T": scene.L, "Freact": 3 * scene.fixed_indices.size}
    return n_times * sum(per_time[name] for name in outputs)


def error_text(exc: BaseException) -> str:
    """A member's recorded error, one line: the library's message with its kind."""
    kind = "invalid scene" if isinstance(exc, SceneError) else type(exc).__name__
    return f"{kind}: {exc}".replace("\n", " ")


class StudyPayload(WorkerPlugin):
    """Installs one study on every worker (``Client.register_plugin``); removed when the study ends."""

    def __init__(self, spec: StudySpec):
        self.spec = spec
        self.name = f"linknet-ensemble-{spec.study_id}"

    def setup(self, worker):
        _RUNTIMES[self.spec.study_id] = StudyRuntime(self.spec)

    def teardown(self, worker):
        runtime = _RUNTIMES.pop(self.spec.study_id, None)
        if runtime is not None:
            runtime.close()


_RUNTIMES: dict[str, "StudyRuntime"] = {}  # study id -> what this worker process holds for it


class StudyRuntime:
    """One study in one worker process: the parsed base scene, and the extracted FMU when there is one."""

    def __init__(self, spec: StudySpec):
        self.spec = spec
        self.base_scene = Scene.from_dict(spec.scene, source=spec.scene.get("name", "scene"))
        self.fmu = FmuRunner(spec.fmu, spec.study_id) if spec.fmu is not None else None
        # looked for once per worker: a worker on a machine without the client's storage returns its trajectories
        self.shard_folder = spec.shards if any(name in OUTPUTS for name in spec.outputs) and \
            sees_folder(spec.shards, spec.study_id) else None
        scene, n = self.base_scene, spec.times.size
        shapes = {"X": (n, scene.K, 3), "U": (n, scene.K, 3), "T": (n, scene.L),
                  "Freact": (n, scene.fixed_indices.size, 3)}
        # what one member returns, by name: its shape (a batch stacks them, member first)
        self.shapes = {name: shapes[name] for name in OUTPUTS if name in spec.outputs}
        self.shapes.update({"max_tension": (), "max_tension_link": (), "min_tension": (), "tip_final": (3,),
                            "error_estimate": (), "error_goal": ()})

    def close(self):
        # the study has ended: a batch still running (cancelled, on a cluster the study did not start) writes no
        # shard into a folder its study has tidied
        self.shard_folder = None
        if self.fmu is not None:
            self.fmu.close()

    def blank_batch(self, count: int) -> dict:
        """The arrays of a batch of ``count`` members, NaN (no link: 0) until a member fills its rows."""
        return {name: np.zeros(count, np.int32) if name == "max_tension_link" else np.full((count, *shape), np.nan)
                for name, shape in self.shapes.items()}

    def run(self, setting: dict) -> dict:
        """One member: the requested outputs at every output time, and the quantities of interest."""
        if self.fmu is not None:
            X, U, T, Freact, error = self.fmu.run(self.spec, setting, self.base_scene)
            goal = math.nan  # the FMU holds its own goal, and logs its crossing itself
        else:
            X, U, T, Freact, error, goal = self._run_library(setting)
        out = {name: array for name, array in zip(OUTPUTS, (X, U, T, Freact)) if name in self.spec.outputs}
        out.update(quantities_of_interest(T, X, self.spec.tip))
        out["error_estimate"], out["error_goal"] = error, goal
        return out

    def _run_library(self, setting: dict):
        """The member's scene (the base scene object itself when the member changes nothing in it, so that what
        is kept per scene, its analysis and simulate's pooled Simulators, serves every such member), then
        ``simulate`` with the member's solver and its constant input force."""
        spec = self.spec
        data = member_scene(spec.scene, spec.parameters, setting)
        scene = self.base_scene if data is None else Scene.from_dict(data, source=self.base_scene.name)
        method, dt, rtol = spec.solver(setting)
        forces = member_forces(spec.parameters, setting, scene.K)
        result = simulate(scene, float(spec.times[-1]), method=method, dt=dt, rtol=rtol,
                          atol=spec.atol if rtol is not None else None, n_out=spec.times.size, forces=forces,
                          progress=False, project_initial=spec.project_initial)
        Freact = _anchor_reactions(scene, result.X, result.T) if "Freact" in spec.outputs else None
        return result.X, result.U, result.T, Freact, result.max_error_estimate, result.error_goal


def _anchor_reactions(scene: Scene, X: np.ndarray, T: np.ndarray) -> np.ndarray:
    """The force the network exerts on each anchored mass at every sample (n, anchors, 3): the library's
    Dynamics.anchor_reactions of each sample's positions and tensions."""
    from linknet_core.dynamics.equations import Dynamics

    dyn = Dynamics(scene)
    return np.stack([dyn.anchor_reactions(x, t) for x, t in zip(X, T)]) if X.shape[0] else \
        np.zeros((0, scene.fixed_indices.size, 3))


def quantities_of_interest(T: np.ndarray, X: np.ndarray, tip: int) -> dict:
    """Largest and smallest tension over the output samples (and the link of the largest), final tip position."""
    if T.shape[1]:
        worst = np.unravel_index(int(np.argmax(T)), T.shape)
        qoi = {"max_tension": float(T[worst]), "max_tension_link": int(worst[1]) + 1, "min_tension": float(T.min())}
    else:
        qoi = {"max_tension": np.nan, "max_tension_link": 0, "min_tension": np.nan}
    qoi["tip_final"] = X[-1, tip]
    return qoi


def run_batch(study_id: str, first: int, settings: list[dict]) -> dict:
    """Members first .. first + len(settings) - 1: one numpy array per output, member first (NaN where a member
    failed), each member's error ('' if none), its wall and CPU time, and this worker's address. Where this
    worker sees the study's shard folder, the batch is written there as a shard (``shard``: its path) and the
    trajectories are left out of the result; where that write fails, they stay in it and ``shard_error`` says why.

    The members' AccuracyWarnings are not raised here: each member's estimate and goal are in the study, which
    warns once, on the client, of the members beyond their goal."""
    runtime = _RUNTIMES.get(study_id)
    if runtime is None:  # the plugin installs the study before a worker takes its tasks
        raise RuntimeError(f"study {study_id} is not installed on worker {get_worker().address}")
    count = len(settings)
    outputs = runtime.blank_batch(count)
    errors = [""] * count
    seconds, cpu_seconds = np.empty(count), np.empty(count)
    # the filters are the process's: on a worker with several threads a batch ending may restore them under
    # another one still running, which then warns (or, the other way round, leaves AccuracyWarnings ignored in
    # that worker); both are about the workers' own stderr, never a member's result
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AccuracyWarning)
        for i, setting in enumerate(settings):
            start, cpu_start = time.perf_counter(), time.thread_time()
            try:
                member = runtime.run(setting)
            except Exception as exc:  # a member's failure is its result; the batch goes on
                errors[i] = error_text(exc)
            else:
                for name, value in member.items():
                    outputs[name][i] = value
            seconds[i], cpu_seconds[i] = time.perf_counter() - start, time.thread_time() - cpu_start
    result = {"first": first, "count": count, "outputs": outputs, "error": errors, "run_seconds": seconds,
              "cpu_seconds": cpu_seconds, "worker": get_worker().address}
    if runtime.shard_folder is not None:
        cpu_start = time.thread_time()
        try:
            result["shard"] = str(write_shard(runtime.shard_folder, study_id, result, OUTPUTS))
        except WriteError as exc:  # the client writes it (and says so if it cannot either)
            result["shard_error"] = str(exc)
        else:
            result["outputs"] = {name: values for name, values in outputs.items() if name not in OUTPUTS}
        result["write_cpu_seconds"] = time.thread_time() - cpu_start
    return result


# ---- FMU members ------------------------------------------------------------------------------------

class FmuError(LinknetError):
    """The FMU refused a member (its own message, logged through the FMI logger, is the text)."""


class _QuietFmuErrors:
    """Stands in for sys.stderr and drops the slave's '[linknet FMU error] ...' lines written while this thread
    runs an FMU member: the FMI logger has them already (they become the member's recorded error), and from a
    LocalCluster's workers they would land on the user's terminal, through the progress bar."""

    MARK = "[linknet FMU error]"

    def __init__(self, stream):
        self.stream = stream
        self.running_member = threading.local()

    def write(self, text):
        if getattr(self.running_member, "active", False) and text.startswith(self.MARK):
            return len(text)
        return self.stream.write(text)

    def __getattr__(self, name):
        return getattr(self.stream, name)



def fmpy_callbacks(log: list):
    """fmpy's FMI 2 callbacks with a logger of their own that appends (status, message) to ``log``; whoever
    instantiates with them keeps them as long as the instance. (fmpy's default logger goes through a proxy in its
    logging library that has one global target for the whole process.)"""
    from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    def logger(env, instance, status, category, message):
        log.append((int(status), message.decode("utf-8", "replace")))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    return callbacks

class FmuRunner:
    """One FMU extracted once per worker process, an instance per worker thread reset between members."""

    def __init__(self, fmu_bytes: bytes, study_id: str):
        from fmpy import extract, read_model_description

        self.directory = tempfile.mkdtemp(prefix=f"linknet-ensemble-{study_id[:12]}-")
        archive = os.path.join(self.directory, "model.fmu")
        with open(archive, "wb") as f:
            f.write(fmu_bytes)
        self.unzipdir = extract(archive, unzipdir=os.path.join(self.directory, "unzipped"))
        self.md = read_model_description(self.unzipdir)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self._local = threading.local()
        self._instances = []
        self._lock = threading.Lock()
        if not isinstance(sys.stderr, _QuietFmuErrors):
            sys.stderr = _QuietFmuErrors(sys.stderr)
        self._stderr = sys.stderr
        self._read = None  # which outputs the FMU has, found at the first member

    def close(self):
        with self._lock:
            for slave, _ in self._instances:
                try:
                    slave.freeInstance()
                except Exception:  # an instance left broken by a failed member has nothing more to free
                    pass
            self._instances.clear()
        shutil.rmtree(self.directory, ignore_errors=True)

    def _instance(self):
        """This thread's instance (FMU instances are not thread-safe), and its log of messages."""
        if getattr(self._local, "slave", None) is None:
            from fmpy.fmi2 import FMU2Slave

            log: list[tuple[int, str]] = []
            callbacks = fmpy_callbacks(log)
            slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                              modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="member")
            # pythonfmu forwards its messages (the reason for a refused member) only with logging on
            slave.instantiate(callbacks=callbacks, loggingOn=True)
            self._local.slave, self._local.log, self._local.fresh = slave, log, True
            self._local.callbacks = callbacks  # ctypes callbacks must outlive the instance
            with self._lock:
                self._instances.append((slave, callbacks))
        return self._local.slave, self._local.log

    def _drop_instance(self):
        slave = self._local.slave
        self._local.slave = None
        with self._lock:
            self._instances = [(s, c) for s, c in self._instances if s is not slave]
        try:
            slave.freeInstance()
        except Exception:
            pass

    def run(self, spec: StudySpec, setting: dict, scene: Scene):
        from fmpy.fmi1 import FMICallException

        slave, log = self._instance()
        self._stderr.running_member.active = True
        try:
            if not self._local.fresh:
                slave.reset()  # pythonfmu re-creates the slave from the FMU's resources: every parameter anew
            self._local.fresh = False
            log.clear()
            return self._simulate(slave, spec, setting, scene)
        except FMICallException as exc:
            errors = [message for status, message in log if status >= 2]  # discard, error, fatal
            raise FmuError(errors[-1] if errors else str(exc)) from None
        except Exception:
            self._drop_instance()  # whatever state it is in, the next member gets a new instance
            raise
        finally:
            self._stderr.running_member.active = False

    def _simulate(self, slave, spec: StudySpec, setting: dict, scene: Scene):
        method, dt, rtol = spec.solver(setting)
        starts: dict[str, float] = {}
        for p in spec.parameters:
            if not p.family.text and p.family.name not in ("step", "tolerance"):
                starts.update({name: float(setting[p.name]) for name in p.fmu_variables()})
        if dt is not None:
            starts["step"] = float(dt)
        if rtol is not None:
            starts["tolerance"] = float(rtol)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        if starts:
            slave.setReal([self.vr[name] for name in starts], list(starts.values()))
        if method is not None:
            slave.setString([self.vr["integrator"]], [method])
        slave.exitInitializationMode()

        if self._read is None:
            self._read = _OutputMap(self.vr, scene)
        read = self._read
        n = spec.times.size
        values = np.empty((n, len(read.vrs)))
        values[0] = slave.getReal(read.vrs)
        for i in range(1, n):
            slave.doStep(currentCommunicationPoint=float(spec.times[i - 1]),
                         communicationStepSize=float(spec.times[i] - spec.times[i - 1]))
            values[i] = slave.getReal(read.vrs)
        return (*read.split(values), read.error_estimate(values))


class _OutputMap:
    """Where each output of the FMU goes in the (time, mass, axis) and (time, link) arrays. An FMU built with
    ``--outputs`` exposes X and U for some masses only: the others stay NaN."""

    def __init__(self, vr: dict, scene: Scene):
        self.K, self.L, self.fixed = scene.K, scene.L, scene.fixed_indices
        names = ([f"X[{k + 1},{i + 1}]" for k in range(self.K) for i in range(3)]
                 + [f"U[{k + 1},{i + 1}]" for k in range(self.K) for i in range(3)]
                 + [f"T[{l + 1}]" for l in range(self.L)]
                 + [f"Freact[{k + 1},{i + 1}]" for k in self.fixed for i in range(3)])
        self.present = np.array([name in vr for name in names])
        self.vrs = [vr[name] for name in np.array(names)[self.present]]
        # the FMU's error estimate (an FMU without that output: NaN), read last
        self.has_error = "error_estimate" in vr
        if self.has_error:
            self.vrs.append(vr["error_estimate"])

    def error_estimate(self, values: np.ndarray) -> float:
        """The largest estimated position error over the samples read, m (NaN if the FMU reports none)."""
        return float(values[:, -1].max()) if self.has_error else math.nan

    def split(self, values: np.ndarray):
        if self.has_error:
            values = values[:, :-1]
        full = np.full((values.shape[0], self.present.size), np.nan)
        full[:, self.present] = values
        n, K3 = values.shape[0], 3 * self.K
        X = full[:, :K3].reshape(n, self.K, 3)
        U = full[:, K3:2 * K3].reshape(n, self.K, 3)
        T = full[:, 2 * K3:2 * K3 + self.L]
        Freact = full[:, 2 * K3 + self.L:].reshape(n, self.fixed.size, 3)
        return X, U, T, Freact


@dataclass(frozen=True)
class FmuFacts:
    """What a study needs to know of an FMU before running it: its variables' start values (parameters, the
    integrator's name) and, for an FMU built by build_fmu.py on pythonfmu, the scene it carries (a native FMU
    carries none)."""

    starts: dict  # variable name -> start value (float, or str for the integrator)
    scene: dict | None

    def defaults(self) -> dict:
        """The FMU's own integrator, step and tolerance."""
        return {name: self.starts[name] for name in ("integrator", "step", "tolerance") if name in self.starts}

    def check_matches(self, scene: Scene, source: str) -> None:
        """Refuse a scene the FMU was not built from: its masses, lengths and gravity must be the FMU's
        parameter start values."""
        expected = {f"M[{k + 1}]": scene.mass[k] for k in scene.free_indices}
        expected.update({f"R[{l + 1}]": scene.length[l] for l in range(scene.L)})
        expected.update({f"g[{i + 1}]": scene.gravity[i] for i in range(3)})
        extra = sorted(n for n in self.starts if n[:2] in ("M[", "R[") and n not in expected)
        for name, value in expected.items():
            if name not in self.starts or not np.isclose(self.starts[name], value, rtol=1e-12, atol=0):
                found = f"is {self.starts[name]:g}" if name in self.starts else "does not exist"
                raise LinknetError(f"{source} was not built from scene {scene.name}: its {name} {found}, the scene's "
                                   f"is {value:g}; give the scene the FMU was built from")
        if extra:
            raise LinknetError(f"{source} was not built from scene {scene.name}: it has {extra[0]}, the scene has no "
                               "such mass or link")


def read_fmu(fmu_bytes: bytes, source: str) -> FmuFacts:
    """Start values from modelDescription.xml, and resources/linknet_scene.json when the FMU has one."""
    import io
    import xml.etree.ElementTree as ET

    try:
        with zipfile.ZipFile(io.BytesIO(fmu_bytes)) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            scene = json.loads(z.read("resources/linknet_scene.json")) if "resources/linknet_scene.json" in \
                z.namelist() else None
    except (zipfile.BadZipFile, KeyError, ET.ParseError, json.JSONDecodeError) as exc:
        raise LinknetError(f"{source} is not an FMU: {exc}") from None
    starts = {}
    for variable in root.iter("ScalarVariable"):
        for kind, convert in (("Real", float), ("String", str)):
            value = variable.find(kind)
            if value is not None and value.get("start") is not None:
                starts[variable.get("name")] = convert(value.get("start"))
    if not any(name.startswith("R[") or name.startswith("M[") for name in starts):
        raise LinknetError(f"{source} is not a linknet network FMU (it has no parameters M[k], R[l])")
    return FmuFacts(starts, scene)
