"""A small co-simulation master for FMI 2.0 CS FMUs, on fmpy's FMU2Slave (copy it freely).

    with Slave("chain.fmu", "chain") as chain, Slave("pd.fmu", "pd") as pd:
        ...
        chain.set({"F[1,3]": 1.0}); chain.step(t, h)

The examples in this folder use it with a fixed communication step h and the usual explicit
(zero-order hold) coupling: at each communication point the master reads the outputs that have
no direct feedthrough (positions, velocities), evaluates the components that have it
(controller, spring-damper) and sets their outputs as the inputs held over [t, t + h]. The
coupling error is then O(h) (first order), which the examples measure.

pythonfmu 0.7.0 notes (docs/fmu.md): instantiate with loggingOn=True, or pythonfmu drops every
log message; a process that loaded pythonfmu FMUs may abort at exit after all work is done
(heap corruption while finalizing Python), so scripts end with `finish()` (os._exit).
"""
from __future__ import annotations

import os
import sys

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


class Slave:
    """One FMU instance, variables addressed by name."""

    def __init__(self, path, name, start: dict | None = None, strings: dict | None = None):
        self.path = str(path)
        self.md = read_model_description(self.path)
        self.unzipdir = extract(self.path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=True)  # pythonfmu forwards log messages only with loggingOn
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        if start:
            self.set(start)
        for key, value in (strings or {}).items():
            self.fmu.setString([self.vr[key]], [value])
        self.fmu.exitInitializationMode()

    def set(self, values: dict):
        self.fmu.setReal([self.vr[k] for k in values], [float(v) for v in values.values()])

    def get(self, names) -> np.ndarray:
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    def vector(self, name: str, k: int | None = None) -> list:
        """['X[k,1]', 'X[k,2]', 'X[k,3]'] or ['F[1]', 'F[2]', 'F[3]']."""
        return [f"{name}[{k},{i}]" if k is not None else f"{name}[{i}]" for i in (1, 2, 3)]

    def step(self, t: float, h: float):
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_container(config, out, name: str):
    """fmpy's container FMU for ``config`` as out/name.fmu (unpacked in out/name). fmpy 0.3.x writes the
    connections' types with FMI 2 names ("Real", "Integer") into resources/container.json, where its own container
    binary expects FMI 3 names ("Float64", "Int32"): they are renamed in the written FMU."""
    import json
    import zipfile

    from fmpy.container_fmu.cli import create_container_fmu

    unzipdir = out / name
    unzipdir.mkdir(parents=True, exist_ok=True)
    fmu = out / f"{name}.fmu"
    if fmu.exists():
        fmu.unlink()
    create_container_fmu(config, unzipdir, fmu)
    with zipfile.ZipFile(fmu) as z:
        items = [(i.filename, z.read(i)) for i in z.infolist()]
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for item, data in items:
            if item == "resources/container.json":
                cfg = json.loads(data)
                for c in cfg["connections"]:
                    c["variableType"] = {"Real": "Float64", "Integer": "Int32"}.get(c["variableType"],
                                                                                    c["variableType"])
                data = json.dumps(cfg, indent=1).encode()
            z.writestr(item, data)
    return fmu


def finish(code: int = 0):
    """Flush and leave without running pythonfmu's exit-time finalization (see module doc)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def observed_orders(steps, errors) -> list:
    """log2-type orders between successive (h, error) pairs."""
    return [float(np.log(errors[i] / errors[i + 1]) / np.log(steps[i] / steps[i + 1]))
            for i in range(len(steps) - 1)]
