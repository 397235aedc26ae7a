#!/usr/bin/env python3
"""The native FMU (build_fmu.py --native) against the pythonfmu FMU: measures, prints and saves; asserts nothing.

    python -m benchmarks.bench_fmu_native [--quick] [--scenes chain_10 chain_100] [--out build/bench_fmu_native.json]

1. FMU size (bytes of the .fmu) of both kinds.
2. Cold start: seconds from fmi2Instantiate to the end of the first doStep (setup, initialization and one
   communication step of 10 ms included), each in a fresh process of the plain C host
   (tests/fmu_native/native_host.c, `coldstart`), which also reports its dlopen of the binary. The native FMU
   runs with no Python in the host's environment; the pythonfmu FMU needs its Python (it starts an interpreter
   and imports linknet_core, numpy and scipy inside fmi2Instantiate).
3. Per-doStep overhead of the native FMU over the core's own ln_advance, from C: tests/fmu_native/timing_host.c
   is compiled with the FMU's own sources/ (same flags as the FMU's binary) and times, in one process,
   fmi2SetReal + fmi2DoStep of an FMI instance against ln_advance on a bare model of the same scene at the same
   state, in alternating runs of N calls from the same saved state (best of R); the final states must agree bit
   for bit. RATTLE with 1 or 10 steps per 1 ms communication step; one input set per call, or all of them. The
   static truss (ln_advance moves t only) shows the glue's cost alone.
4. The pythonfmu FMU's per-doStep cost from the same C host (dlopen, `stepbench`) against
   linknet_core.Simulator.advance timed in this process, and the native FMU's from the same host.
Each figure is the best (minimum) of repeated runs: the machine is shared, other processes only add time.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "fmu_src"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402
from benchmarks.output import BUILD, build_path, write_text  # noqa: E402
from native.build import CFLAGS  # noqa: E402

HOSTS = ROOT / "tests" / "fmu_native"


def compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if not cc:
        raise SystemExit("bench_fmu_native: no C compiler (cc, gcc or clang) on PATH")
    return cc


class Fmu:
    def __init__(self, path: Path):
        from fmpy import read_model_description
        self.path = path
        self.dir = path.with_suffix("")
        shutil.rmtree(self.dir, ignore_errors=True)
        with zipfile.ZipFile(path) as z:
            z.extractall(self.dir)
        md = read_model_description(str(path))
        self.md, self.ident, self.guid = md, md.coSimulation.modelIdentifier, md.guid
        self.vr = {v.name: v.valueReference for v in md.modelVariables}

    def inputs(self) -> list[int]:
        return [v.valueReference for v in self.md.modelVariables if v.name.startswith("F[")]


def no_python_env(tmp: Path) -> dict:
    empty = tmp / "empty_path"
    empty.mkdir(exist_ok=True)
    return {"PATH": str(empty)}


def python_env() -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "LD_PRELOAD"}
    env["NATIVE_HOST_FAST_EXIT"] = "1"  # pythonfmu 0.7.0 can hang in a normal exit (docs/contract.md)
    return env


def run(cmd, env=None, timeout=600) -> dict:
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, env=env, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd[:4]))} ... failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    out = {}
    for line in proc.stdout.splitlines():
        key, _, value = line.partition(" ")
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out


def cold_start(host, fmu: Fmu, env, repeats: int) -> dict:
    samples = [run([host, "coldstart", fmu.dir, fmu.ident, fmu.guid, 0.01], env=env) for _ in range(repeats)]
    first = [s["instantiate_to_first_step"] for s in samples]
    load = [s["dlopen"] for s in samples]
    return dict(median_s=statistics.median(first), min_s=min(first), max_s=max(first),
                dlopen_median_s=statistics.median(load), runs=repeats)


def timing_host(cc: str, fmu: Fmu, where: Path) -> Path:
    files = [f for f in fmu.md.buildConfigurations[0].sourceFileSets[0].sourceFiles]
    exe = where / f"timing_{fmu.ident}"
    sources = fmu.dir / "sources"
    cmd = [cc] + CFLAGS + ["-I", str(sources), "-o", str(exe), str(HOSTS / "timing_host.c")] + \
          [str(sources / f) for f in files] + ["-lm"]
    subprocess.run(cmd, check=True, capture_output=True)
    return exe


def simulator_advance(scene, n: int, h: float, step: float, repeats: int, k: int) -> float:
    """Seconds per Simulator.advance (one input changed per call), best of repeats runs of n calls."""
    sim = ln.Simulator(scene, method="rattle", dt=step, error_estimate=False)
    start = sim.get_state()
    F = np.zeros((scene.K, 3))
    values = 0.1 * np.sin(0.37 * np.arange(n))
    best = 1e300
    for _ in range(repeats):
        sim.set_state(start)
        t = 0.0
        t0 = time.perf_counter()
        for i in range(n):
            F[k, 2] = values[i]
            sim.advance(t + h, F)
            t += h
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="CI-sized: fewer scenes and repeats")
    p.add_argument("--scenes", nargs="+")
    p.add_argument("--out", help="results (JSON; default build/bench_fmu_native.json); not inside docs/")
    a = p.parse_args(argv)
    out = build_path("bench_fmu_native.json", a.out, parser=p)
    scenes = a.scenes or (["chain_10", "chain_100"] if a.quick else ["chain_10", "chain_100", "net_10x10",
                                                                      "redundant_truss"])
    cold_repeats, py_cold_repeats = (5, 2) if a.quick else (21, 5)
    N, R = (300, 7) if a.quick else (300, 31)
    cc = compiler()
    work = BUILD / "bench_fmu_native"  # the FMUs
    work.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="bench_fmu_native_"))
    host = tmp / "native_host"
    subprocess.run([cc, "-std=c99", "-O2", "-o", str(host), str(HOSTS / "native_host.c"), "-ldl", "-lpthread", "-lm"],
                   check=True)
    bare = no_python_env(tmp)
    results = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                   commit=subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                         cwd=ROOT).stdout.strip(),
                   load=os.getloadavg(), compiler=cc, flags=CFLAGS, scenes={})
    for name in scenes:
        path = ROOT / "models" / f"{name}.json"
        t0 = time.perf_counter()
        native = Fmu(build_fmu.build_scene_fmu(str(path), work / f"{name}_native.fmu", quiet=True, native=True))
        build_native = time.perf_counter() - t0
        t0 = time.perf_counter()
        python = Fmu(build_fmu.build_scene_fmu(str(path), work / f"{name}_pythonfmu.fmu", quiet=True))
        build_python = time.perf_counter() - t0
        r = results["scenes"][name] = dict(
            size_native=native.path.stat().st_size, size_pythonfmu=python.path.stat().st_size,
            build_native_s=build_native, build_pythonfmu_s=build_python)
        r["cold_native"] = cold_start(host, native, bare, cold_repeats)
        r["cold_pythonfmu"] = cold_start(host, python, python_env(), py_cold_repeats)

        # 3. native glue over ln_advance (one process, same sources)
        exe = timing_host(cc, native, tmp)
        inputs = native.inputs()
        one = inputs[-1]
        for label, step in (("1 step", 1e-3), ("10 steps", 1e-4)):
            one_in = run([exe, native.dir.resolve() / "resources", N, 1e-3, R, step, one])
            all_in = run([exe, native.dir.resolve() / "resources", N, 1e-3, R, step] + inputs) if inputs else one_in
            r[f"glue {label}"] = dict(
                core_advance_ns=one_in["core_advance"], fmu_dostep_ns=one_in["fmu_dostep"],
                core_one_input_ns=one_in["core_advance_one_input"],
                fmu_setreal_dostep_one_input_ns=one_in["fmu_setreal_dostep_one_input"],
                fmu_setreal_one_ns=one_in["fmu_setreal_one"],
                core_all_inputs_ns=all_in["core_advance_all_inputs"],
                fmu_setreal_dostep_all_inputs_ns=all_in["fmu_setreal_dostep_all_inputs"],
                fmu_setreal_all_ns=all_in["fmu_setreal_all"], n_inputs=len(inputs),
                identical=bool(one_in["identical"] == 1 and all_in["identical"] == 1))

        # 4. both FMUs from the C host (dlopen), against Simulator.advance in this process
        scene = ln.load_scene(path)
        k_py = int(python.md.modelVariables[[v.valueReference for v in python.md.modelVariables].index(one)]
                   .name.split("[")[1].split(",")[0]) - 1
        for label, step in (("1 step", 1e-3), ("10 steps", 1e-4)):
            nat = run([host, "stepbench", native.dir, native.ident, native.guid, N, 1e-3, R, native.vr["step"], step,
                       one], env=bare)
            pyf = run([host, "stepbench", python.dir, python.ident, python.guid, N, 1e-3, max(3, R // 3),
                       python.vr["step"], step, python.vr[python.md.modelVariables[one].name]], env=python_env())
            adv = simulator_advance(scene, N, 1e-3, step, max(3, R // 3), k_py)
            r[f"hosts {label}"] = dict(native_setreal_dostep_ns=nat["setreal_dostep"], native_dostep_ns=nat["dostep"],
                                       pythonfmu_setreal_dostep_ns=pyf["setreal_dostep"],
                                       pythonfmu_dostep_ns=pyf["dostep"], simulator_advance_ns=1e9 * adv)
        print(f"{name}: done", file=sys.stderr)
    shutil.rmtree(tmp, ignore_errors=True)
    write_text(out, json.dumps(results, indent=1))
    report(results)
    return 0


def report(results: dict) -> None:
    print(f"# native FMU vs pythonfmu FMU ({results['date']}, {results['commit']}, load {results['load'][0]:.1f}, "
          f"{results['compiler']} {' '.join(results['flags'])})\n")
    print("| scene | size native | size pythonfmu | cold start native (median, min) | cold start pythonfmu (median) "
          "| dlopen native |")
    print("|---|---|---|---|---|---|")
    for name, r in results["scenes"].items():
        cn, cp = r["cold_native"], r["cold_pythonfmu"]
        print(f"| {name} | {r['size_native'] / 1024:.0f} KiB | {r['size_pythonfmu'] / 1024:.0f} KiB | "
              f"{1e3 * cn['median_s']:.3f} ms, {1e3 * cn['min_s']:.3f} ms | {1e3 * cp['median_s']:.0f} ms | "
              f"{1e3 * cn['dlopen_median_s']:.3f} ms |")
    print("\nPer call, native FMU over the core's own ln_advance (same sources, one process; ns):\n")
    print("| scene | RATTLE steps | ln_advance | fmi2DoStep | overhead | ln_advance + 1 input | setReal(1) + doStep "
          "| overhead | all inputs: core | setReal(all) + doStep | overhead | bit-identical |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r in results["scenes"].items():
        for label in ("1 step", "10 steps"):
            g = r[f"glue {label}"]
            print(f"| {name} | {label.split()[0]} | {g['core_advance_ns']:.0f} | {g['fmu_dostep_ns']:.0f} | "
                  f"{g['fmu_dostep_ns'] - g['core_advance_ns']:+.0f} | {g['core_one_input_ns']:.0f} | "
                  f"{g['fmu_setreal_dostep_one_input_ns']:.0f} | "
                  f"{g['fmu_setreal_dostep_one_input_ns'] - g['core_one_input_ns']:+.0f} | "
                  f"{g['core_all_inputs_ns']:.0f} ({g['n_inputs']}) | {g['fmu_setreal_dostep_all_inputs_ns']:.0f} | "
                  f"{g['fmu_setreal_dostep_all_inputs_ns'] - g['core_all_inputs_ns']:+.0f} | {g['identical']} |")
    print("\nFrom the C host (dlopen), per setReal(1 input) + doStep, against Simulator.advance in Python (us):\n")
    print("| scene | RATTLE steps | native FMU | pythonfmu FMU | Simulator.advance "
          "| pythonfmu over Simulator.advance |")
    print("|---|---|---|---|---|---|")
    for name, r in results["scenes"].items():
        for label in ("1 step", "10 steps"):
            h = r[f"hosts {label}"]
            print(f"| {name} | {label.split()[0]} | {h['native_setreal_dostep_ns'] / 1e3:.2f} | "
                  f"{h['pythonfmu_setreal_dostep_ns'] / 1e3:.2f} | {h['simulator_advance_ns'] / 1e3:.2f} | "
                  f"{(h['pythonfmu_setreal_dostep_ns'] - h['simulator_advance_ns']) / 1e3:+.2f} |")


if __name__ == "__main__":
    sys.exit(main())
