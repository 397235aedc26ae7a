"""Helpers of the native FMU tests (the fixtures are in conftest.py): FMUs built once per session, runs of the
plain C host with no Python anywhere in its environment, and the same runs on linknet_core's Simulator."""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
for p in (ROOT, ROOT / "tests", ROOT / "fmu_src"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

import build_fmu  # noqa: E402

MODELS = ROOT / "models"
SCENES = sorted(p.stem for p in MODELS.glob("*.json"))
METHODS = ["rattle", "yoshida4", "suzuki4", "yoshida6", "yoshida8", "dopri5", "dop853"]
GCC = shutil.which("gcc") or shutil.which("cc")
CLANG = shutil.which("clang")


@dataclass
class Built:
    """An FMU, extracted, with its identity and variables by name."""

    path: Path
    dir: Path
    ident: str
    guid: str
    vr: dict = field(default_factory=dict)
    md: object = None

    def vrs(self, prefix: str) -> list[int]:
        return [v.valueReference for v in self.md.modelVariables if v.name.startswith(prefix + "[")]

    def names(self, prefix: str) -> list[str]:
        return [v.name for v in self.md.modelVariables if v.name.startswith(prefix + "[")]


_cache: dict = {}


def compile_host(tmp_path_factory, source: str, *libraries: str) -> Path:
    """A C host of this folder (``source``: its .c file) compiled warning-free into a test's temporary folder; the
    test is skipped where there is no C compiler."""
    if GCC is None:
        pytest.skip("no C compiler (apt-get install gcc)")
    name = Path(source).stem
    exe = tmp_path_factory.mktemp(name) / name
    subprocess.run([GCC, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(HERE / source),
                    *libraries], check=True)
    return exe


def built(root: Path, scene: str | Path, native: bool = True, **options) -> Built:
    """The FMU of a scene (name in models/ or a path), built once per session and options, and extracted."""
    from fmpy import read_model_description
    path = Path(scene) if str(scene).endswith(".json") else MODELS / f"{scene}.json"
    key = (str(path), native, tuple(sorted(options.items())))
    if key not in _cache:
        tag = "_".join(f"{k}{v}" for k, v in sorted(options.items())).replace("/", "_").replace(",", "-")
        out = root / f"{path.stem}{'_native' if native else '_pythonfmu'}{'_' + tag if tag else ''}.fmu"
        build_fmu.build_scene_fmu(str(path), out, quiet=True, native=native, **options)
        where = out.with_suffix("")
        with zipfile.ZipFile(out) as z:
            z.extractall(where)
        md = read_model_description(str(out))
        _cache[key] = Built(out, where, md.coSimulation.modelIdentifier, md.guid,
                            {v.name: v.valueReference for v in md.modelVariables}, md)
    return _cache[key]


def write_scenes(root: Path, scenes: dict) -> dict[str, Path]:
    """Each scene's data (name: dict) written to root/<name>.json; the paths by name."""
    paths = {}
    for name, data in scenes.items():
        paths[name] = root / f"{name}.json"
        paths[name].write_text(json.dumps(data))
    return paths


def fmpy_instance(fmu: Built, name: str, log: list):
    """(FMU2Slave instantiated, its callbacks): fmpy's FMU2Slave of ``fmu`` with a logger of its own that appends
    (status, message) to ``log`` (ensemble.members.fmpy_callbacks). The caller keeps the callbacks as long as the
    instance: fmpy's default logger goes through a proxy whose one global target other instances in the process
    leave behind (a crash in the FMU's first log call)."""
    from fmpy.fmi2 import FMU2Slave

    from linknet_core.ensemble.members import fmpy_callbacks

    callbacks = fmpy_callbacks(log)
    slave = FMU2Slave(guid=fmu.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident, instanceName=name)
    slave.instantiate(callbacks=callbacks, loggingOn=False)
    return slave, callbacks


def run_host(host: Path, env: dict, command: str, fmu: Built, *args, timeout: float = 120) -> str:
    """Run the C host on an FMU; its stdout (fails the test on a non-zero exit, with the host's stderr)."""
    cmd = [str(host), command, str(fmu.dir), fmu.ident, fmu.guid] + [str(a) for a in args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    assert proc.returncode == 0, f"{' '.join(cmd[:6])} ... exited {proc.returncode}\n{proc.stderr[-3000:]}"
    return proc.stdout


def parse_rows(text: str) -> np.ndarray:
    return np.array([[float(x) for x in line.split(",")] for line in text.split()])


# ---------------------------------------------------------------------------- the runs compared
N_STEPS, H = 5, 0.01          # a few communication steps: every integrator, every scene, in seconds
AMPLITUDE_X, AMPLITUDE_Z, OMEGA = 0.5, 2.0, 20.0


def input_mass(fmu: Built) -> int:
    """1-based number of the mass that gets the force input: the last one with inputs."""
    return int(fmu.names("F")[-1].split("[")[1].split(",")[0])


def input_force(k: int, K: int, t: float) -> np.ndarray:
    F = np.zeros((K, 3))
    F[k - 1, 0] = AMPLITUDE_X
    F[k - 1, 2] = AMPLITUDE_Z * math.cos(OMEGA * t)  # libm's cos, as the C host
    return F


def output_names(fmu: Built) -> list[str]:
    """The outputs the runs compare: X, U, T, Freact and, last, the error estimate (m)."""
    return fmu.names("X") + fmu.names("U") + fmu.names("T") + fmu.names("Freact") + ["error_estimate"]


def host_options(fmu: Built, method: str | None = None, parameters: dict | None = None) -> list[str]:
    k = input_mass(fmu)
    opts = ["-i", f"{fmu.vr[f'F[{k},1]']}={AMPLITUDE_X!r}", "-i", f"{fmu.vr[f'F[{k},3]']}={AMPLITUDE_Z!r},{OMEGA!r}"]
    if method:
        opts += ["-m", f"{fmu.vr['integrator']}={method}"]
    for name, value in (parameters or {}).items():
        opts += ["-p", f"{fmu.vr[name]}={value!r}"]
    for name in output_names(fmu):
        opts += ["-o", str(fmu.vr[name])]
    return opts


def library_rows(scene, fmu: Built, method: str, step=1e-3, tolerance=1e-8, n=N_STEPS, h=H, t0=0.0) -> np.ndarray:
    """The same run on linknet_core's Simulator: t, then the outputs in output_names order."""
    import linknet_core as ln
    kwargs = dict(rtol=tolerance) if ln.METHODS[method].adaptive else dict(dt=step)
    if t0:
        kwargs["t0"] = t0  # the scene's initial state given at t0
    sim = ln.Simulator(scene, method=method, **kwargs)
    k = input_mass(fmu)
    picks = []
    for name in output_names(fmu):
        kind, _, idx = name.partition("[")
        idx = [int(i) - 1 for i in idx.rstrip("]").split(",")] if idx else []
        picks.append((kind, idx))
    fixed_row = {int(m): j for j, m in enumerate(scene.fixed_indices)}
    rows = []
    for step_i in range(n + 1):
        t = t0 + step_i * h
        F = input_force(k, scene.K, t)
        o = sim.outputs(F)
        row = [t]
        for kind, idx in picks:
            if kind == "error_estimate":  # the companion's gap at t (the library's own companion run)
                row.append(sim.error_estimate)
            elif kind == "T":
                row.append(o["T"][idx[0]])
            elif kind == "Freact":
                row.append(np.asarray(o["Freact"])[fixed_row[idx[0]], idx[1]])
            else:
                row.append(o[kind][idx[0], idx[1]])
        rows.append(row)
        if step_i < n:
            sim.advance(t + h, F)
    return np.array(rows)


def assert_round_off(a: np.ndarray, b: np.ndarray, what: str, names: list[str] | None = None):
    """Equal to round-off: the outputs of a few steps agree to ~1e-12 of their own size. names: the columns after t
    (output_names); the error estimate, a gap between two runs' positions, is held to the positions' size (its
    round-off is that of the positions it subtracts, whatever its own size); an anchor's impulse Jreact to the impulse
    the anchors' forces Freact carry over one communication step (where no jump happens, Jreact is the round-off of a
    velocity projection, ~1e-17 N s, whose digits the FMU's compiler (clang, through zig) and the library's (gcc)
    round differently)."""
    assert a.shape == b.shape, f"{what}: shapes {a.shape} vs {b.shape}"
    scale = np.maximum(np.abs(b).max(axis=0), 1e-300)

    def columns(prefix):
        return [1 + j for j, name in enumerate(names) if name.startswith(prefix)]
    if names is not None and "error_estimate" in names:
        j = 1 + names.index("error_estimate")
        scale[j] = max(scale[j], np.abs(b[:, columns("X[")]).max() if columns("X[") else 1.0)
    if names is not None and columns("Jreact[") and columns("Freact[") and b.shape[0] > 1:
        step_impulse = np.abs(b[:, columns("Freact[")]).max() * np.diff(b[:, 0]).max()
        for j in columns("Jreact["):
            scale[j] = max(scale[j], step_impulse)
    err = np.abs(a - b) / scale
    worst = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() <= 1e-11, f"{what}: worst relative difference {err.max():.3g} at row {worst[0]}, column {worst[1]}"
