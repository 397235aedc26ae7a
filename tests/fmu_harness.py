"""Shared helpers of the FMU tests (tests/test_fmu_*.py).

* `build_cached` builds each FMU once per test session (building never loads the FMU binary).
* `run_client` runs an FMU client (fmpy or the C host) in a fresh subprocess: pythonfmu 0.7.0
  can corrupt the heap while its binary finalizes Python at process exit ("free(): invalid
  pointer", exit 134) *after* all results were produced, especially with numpy loaded. A client
  writes its results to an .npz file, prints a completion marker and leaves with os._exit(0)
  (skipping the library destructors); should an abort still happen after the marker, the
  results are complete and are used. Any other failure fails the test with the client's output.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
DONE = "LINKNET-FMU-CLIENT-DONE"

sys.path.insert(0, str(ROOT))
import build_fmu  # noqa: E402

_cache: dict = {}


def build_cached(tmp_root: Path, target: str, out_name: str | None = None, **options) -> Path:
    """Build `target` (a scene path or a component name) once per session and options."""
    key = (target, tuple(sorted(options.items())))
    if key not in _cache:
        name = out_name or (Path(target).stem if target.endswith(".json") else target)
        suffix = "_" + "_".join(f"{k}{v}" for k, v in sorted(options.items())) if options else ""
        out = tmp_root / f"{name}{suffix}.fmu".replace("/", "_")
        if target.endswith(".json"):
            build_fmu.build_scene_fmu(target, out, quiet=True, **options)
        else:
            build_fmu.build_component_fmu(target, out, quiet=True, **options)
        _cache[key] = out
    return _cache[key]


CLIENT_PROLOGUE = f"""
import os, sys
sys.path.insert(0, {str(ROOT)!r})
import numpy as np
_RESULTS = {{}}
def save(**arrays):
    _RESULTS.update(arrays)
def _finish(path):
    np.savez(path, **_RESULTS)
    sys.stdout.write("\\n{DONE}\\n")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)  # skip pythonfmu's exit-time finalization (heap corruption, exit 134)
"""


def run_client(code: str, workdir: Path, timeout: float = 240) -> dict:
    """Run client `code` (which calls save(name=array, ...)) in a subprocess; return the arrays."""
    workdir.mkdir(parents=True, exist_ok=True)
    n = len(list(workdir.glob("client_*.py")))
    script = workdir / f"client_{n}.py"
    results = workdir / f"client_{n}.npz"
    script.write_text(CLIENT_PROLOGUE + textwrap.dedent(code) + f"\n_finish({str(results)!r})\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=timeout,
                          cwd=str(workdir))
    finished = DONE in proc.stdout and results.exists()
    aborted_after_results = proc.returncode in (134, -signal.SIGABRT) and finished
    if not (proc.returncode == 0 or aborted_after_results) or not finished:
        raise AssertionError(f"FMU client {script} failed (exit {proc.returncode})\n--- stdout\n{proc.stdout[-4000:]}"
                             f"\n--- stderr\n{proc.stderr[-4000:]}")
    with np.load(results, allow_pickle=False) as z:
        out = {k: z[k] for k in z.files}
    out["_stdout"] = proc.stdout
    return out


def run_host(cmd: list, timeout: float = 120, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)


# Code shared by clients: an FMU2Slave wrapper with a log collector and name-based access.
FMU_CLIENT_LIB = """
import ctypes
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, \\
    fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, defaultCallbacks
from fmpy.fmi1 import FMICallException

LOG = []

def _log(env, instance, status, category, message):
    LOG.append((int(status), message.decode("utf-8", "replace")))

CALLBACKS = fmi2CallbackFunctions()
CALLBACKS.logger = fmi2CallbackLoggerTYPE(_log)
CALLBACKS.allocateMemory = defaultCallbacks.allocateMemory
CALLBACKS.freeMemory = defaultCallbacks.freeMemory

class Fmu:
    '''One FMU instance driven through fmpy's FMU2Slave, addressed by variable names.'''
    def __init__(self, path, name="inst", unzipdir=None):
        self.md = read_model_description(path)
        self.unzipdir = unzipdir or extract(path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(callbacks=CALLBACKS, loggingOn=True)  # pythonfmu logs nothing otherwise
    def init(self, start=None, strings=None):
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        if start:
            self.set(start)
        for k, v in (strings or {}).items():
            self.slave.setString([self.vr[k]], [v])
        self.slave.exitInitializationMode()
    def set(self, values):
        self.slave.setReal([self.vr[k] for k in values], [float(v) for v in values.values()])
    def get(self, names):
        return np.array(self.slave.getReal([self.vr[n] for n in names]))
    def names(self, prefix):
        return [v.name for v in self.md.modelVariables if v.name.startswith(prefix + "[")]
    def step(self, t, h):
        self.slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
"""
