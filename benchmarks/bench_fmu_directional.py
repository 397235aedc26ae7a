"""The cost of one fmi2GetDirectionalDerivative against one fmi2DoStep of the default settings, from a plain C host
(benchmarks/c_reference/directional_timing_host.c: no Python in the host), on both FMU kinds.

    python benchmarks/bench_fmu_directional.py                     # chain_10 and net_10x10, native and pythonfmu
    python benchmarks/bench_fmu_directional.py --scenes chain_10 --kinds native --n 400 --rounds 7

Each FMU is built from models/<scene>.json with the defaults (dop853, rtol 1e-8, the error estimate on) and driven
at its DefaultExperiment's step (0.01 s) from the start values (inputs 0). One directional call: a seed of 1 on the
last force input, the derivatives of every T and Freact. "first" is the first call at a new state (after a doStep):
it prepares the linearization (the tensions and the factorisation of A) and solves once; "next" is a further call
at the same state (one solve with the kept factorisation): each further Jacobian column. Best of the rounds.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
HOST = ROOT / "benchmarks" / "c_reference" / "directional_timing_host.c"

from benchmarks.output import build_path  # noqa: E402


def build_host(out: Path) -> Path:
    cc = os.environ.get("CC", "cc")
    exe = out / "directional_timing_host"
    subprocess.run([cc, "-O2", "-Wall", "-o", str(exe), str(HOST), "-ldl", "-lm"], check=True)
    return exe


def build(scene: str, kind: str, out: Path):
    import build_fmu
    from fmpy import read_model_description
    os.environ.setdefault("LINKNET_FMU_PLATFORMS", "host")  # the native FMU: this machine's binary only
    fmu = out / f"{scene}_{kind}.fmu"
    build_fmu.build_scene_fmu(str(ROOT / "models" / f"{scene}.json"), fmu, quiet=True, native=kind == "native")
    where = fmu.with_suffix("")
    with zipfile.ZipFile(fmu) as z:
        z.extractall(where)
    return where, read_model_description(str(fmu))


def measure(exe: Path, where: Path, md, n: int, rounds: int) -> dict:
    variables = md.modelVariables
    known = [v.valueReference for v in variables if v.causality == "input" and v.name.startswith("F[")][-1]
    unknown = [v.valueReference for v in variables if v.causality == "output" and v.name.startswith(("T[", "Freact["))]
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "LD_PRELOAD"}
    cmd = [str(exe), str(where.resolve()), md.coSimulation.modelIdentifier, md.guid,
           repr(float(md.defaultExperiment.stepSize)), str(n), str(rounds), str(known)] + [str(u) for u in unknown]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd[:7])} ... exited {proc.returncode}: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", default=["chain_10", "net_10x10"])
    p.add_argument("--kinds", nargs="+", choices=("native", "python"), default=["native", "python"])
    p.add_argument("--n", type=int, default=200, help="calls per round")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--out", help="work folder: the FMUs and the C host (default build/bench_directional); not "
                   "inside docs/")
    a = p.parse_args(argv)
    out = build_path("bench_directional", a.out, parser=p)
    out.mkdir(parents=True, exist_ok=True)
    exe = build_host(out)
    print(f"load average {os.getloadavg()[0]:.2f} (2 cores here); best of {a.rounds} rounds of {a.n} calls")
    print("| scene | FMU | one fmi2DoStep | first directional (prepares) | next directional | first / doStep "
          "| next / doStep |")
    print("|---|---|---|---|---|---|---|")
    for scene in a.scenes:
        for kind in a.kinds:
            where, md = build(scene, kind, out)
            r = measure(exe, where, md, a.n, a.rounds)
            d, f, x = r["dostep_s"], r["directional_first_s"], r["directional_next_s"]
            print(f"| {scene} | {kind} | {d * 1e6:.1f} us | {f * 1e6:.2f} us | {x * 1e6:.2f} us | {f / d:.3f} "
                  f"| {x / d:.3f} |", flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} after the runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
