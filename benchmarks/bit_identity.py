"""Bit identity of two trees of linknet_core: every shipped scene x every method x both backends, digested.

For each case (scene, method, backend) the script runs, on whichever linknet_core is imported:

  simulate   ``ln.simulate`` over a short span (its error estimate's companion run included): the native
             point-mass path samples in one call into C there, the others advance and evaluate sample by sample;
  stepping   a ``Simulator`` driven as an FMU drives it: ``advance`` and ``outputs`` with a held input force,
             a snapshot half-way (``get_state``), the run finished, the snapshot restored (``set_state``) and the
             second half run again, the interface Jacobian (``interface_jacobian``) at the end, then ``reset`` and
             one more advance.

and writes the sha256 of the bytes of what came out: ``XUT`` (the X, U and T arrays of the simulate run and of
every stepping output), ``other`` (the simulate run's energy, residuals, kinetic energy and error estimate, its step
counts; the stepping run's anchor reactions, error estimates, the replay's outputs, the Jacobian's blocks, the
reset's advance). A case that fails digests its error's type and text instead, so a refusal must stay the same
refusal. The scenes: models/*.json and models/degenerate/*.json (two of which are refused by design: hypothesis (35)),
and two variants that reach paths no shipped scene does: the crane with its trolley driven by inputs (anchors=),
and chain_10 with drag, quadratic drag and a spring-damper. The methods: every one of ``ln.METHODS`` (fixed steps
at dt 1e-3, error control at rtol 1e-6) and the two defaults (no method and no step: the error-controlled default;
a step and no method: RATTLE).

    python benchmarks/bit_identity.py --out build/bit_identity/after.json        # the imported tree
    python benchmarks/bit_identity.py --trees before=/tmp/seam_before after=/work/main --out build/bit_identity
    python benchmarks/bit_identity.py --compare build/bit_identity/before.json build/bit_identity/after.json

With ``--trees`` the script runs itself once per tree in a fresh process (PYTHONPATH = the tree, working
directory = the tree, by file path so that nothing else shadows the package), then compares the first tree with
each other one. Two trees compared this way should load native libraries built from the same C sources, so that
the comparison isolates the Python (copy one tree's ``linknet_core/native/_linknet*.so`` into the other).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

T_END = 0.01  # s: ten steps of dt
DT = 1e-3
RTOL = 1e-6
N_OUT = 6
REPO = Path(__file__).resolve().parents[1]


def _method_specs(methods) -> list[tuple[str, dict]]:
    specs = []
    for name, cls in methods.items():
        specs.append((name, {"method": name, "rtol": RTOL} if cls.adaptive else {"method": name, "dt": DT}))
    specs.append(("default", {}))
    specs.append(("default_dt", {"dt": DT}))
    return specs


def _scenes(ln, models: Path) -> list[tuple[str, object, dict]]:
    """(name, scene or the error loading it raised, simulate's extra keywords) of every case's scene."""
    out = []
    for path in sorted(models.glob("*.json")) + sorted((models / "degenerate").glob("*.json")):
        name = str(path.relative_to(models))[:-5]
        try:
            out.append((name, ln.load_scene(path), {}))
        except Exception as exc:  # noqa: BLE001 - a refusal is digested as what it is
            out.append((name, exc, {}))
    crane = json.loads((models / "crane.json").read_text())
    for mass in crane["masses"]:
        if mass.get("driven"):
            mass["motion"] = {"kind": "input"}
    crane["name"] = "crane_input"
    crane.pop("fmu", None)  # the FMU's settings: not a scene field
    scene = ln.Scene.from_dict(crane)
    n = scene.input_driven_indices.size
    hold = (scene.X0[scene.input_driven_indices], np.tile([0.5, 0.0, 0.0], (n, 1)), np.tile([2.0, 0.0, 0.0], (n, 1)))
    out.append(("crane_input", scene, {"anchors": hold}))
    chain = json.loads((models / "chain_10.json").read_text())
    chain["name"] = "chain_10_forces"
    free = [m for m in chain["masses"] if not m.get("fixed")]
    for i, mass in enumerate(free):
        mass["drag"] = 0.05 * (i + 1)
        mass["quadratic_drag"] = 0.02
    chain["springs"] = [{"a": free[0]["name"], "b": free[-1]["name"], "stiffness": 30.0, "damping": 0.4}]
    out.append(("chain_10_forces", ln.Scene.from_dict(chain), {}))
    return out


def _digest(*parts) -> str:
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(np.ascontiguousarray(part, np.float64).tobytes())
        elif isinstance(part, (int, float, np.floating, np.integer)):
            h.update(np.float64(part).tobytes())
        else:
            h.update(repr(part).encode())
    return h.hexdigest()


def _failure(exc: BaseException) -> dict:
    text = f"{type(exc).__name__}: {exc}"
    return {"XUT": "error " + _digest(text)[:16], "other": "error " + _digest(text)[:16], "error": text[:300]}


def _simulate_case(ln, scene, spec: dict, backend: str, extra: dict) -> dict:
    res = ln.simulate(scene, T_END, n_out=N_OUT, progress=False, backend=backend, **spec, **extra)
    stats = {k: res.stats.get(k) for k in ("steps", "rejected", "split", "finest_split", "companion_steps",
                                           "anchor_jumps", "floor_stops", "floor_reached", "rhs_evaluations")}
    return {"XUT": _digest(res.X, res.U, res.T),
            "other": _digest(res.t, res.energy, res.residual, res.velocity_residual, res.kinetic,
                             res.error_estimate, res.error_goal, str(res.error_failure), json.dumps(stats))}


def _stepping_case(ln, scene, spec: dict, backend: str, extra: dict) -> dict:
    sim = ln.Simulator(scene, backend=backend, **spec)
    F = np.zeros((scene.K, 3))
    F[~scene.fixed] = (0.3, -0.2, 0.1)
    hold = extra.get("anchors")
    times = np.linspace(0.0, T_END, N_OUT)
    main, other = [], []

    def record(out, into):
        into.append(out["X"])
        into.append(out["U"])
        into.append(out["T"])
        other.extend((out["Freact"], out["error_estimate"], out.get("impulse", np.zeros(0))))

    record(sim.outputs(F, anchors=hold), main)
    half = N_OUT // 2
    snapshot = None
    for i in range(1, N_OUT):
        sim.advance(times[i], F, anchors=hold if i == 1 else None)
        record(sim.outputs(F), main)
        if i == half:
            snapshot = sim.get_state()
    other.append(np.asarray(sim.integrator.stats.as_dict().get("steps", 0), float))
    sim.set_state(snapshot)
    replay = []
    for i in range(half + 1, N_OUT):
        sim.advance(times[i], F)
        record(sim.outputs(F), replay)
    other.extend(replay)
    try:
        jacobian = sim.interface_jacobian(F)
        for key in sorted(jacobian.blocks):
            other.append(repr(key))
            other.append(np.asarray(jacobian.blocks[key], float))
    except Exception as exc:  # noqa: BLE001 - a Jacobian that cannot be taken is part of the digest
        other.append(f"jacobian {type(exc).__name__}: {exc}")
    sim.reset()
    sim.advance(times[1], F, anchors=hold)
    record(sim.outputs(F), other)
    return {"XUT": _digest(*main), "other": _digest(*other)}


def run_all(out_path: Path) -> dict:
    import linknet_core as ln
    from linknet_core.clib import library

    warnings.simplefilter("ignore")  # accuracy warnings of these short runs are not what is compared
    cases = {}
    start = time.perf_counter()
    for scene_name, scene, extra in _scenes(ln, REPO / "models"):
        for method_name, spec in _method_specs(ln.METHODS):
            for backend in ("numpy", "native"):
                for kind, run in (("simulate", _simulate_case), ("stepping", _stepping_case)):
                    key = f"{scene_name} | {method_name} | {backend} | {kind}"
                    if isinstance(scene, Exception):
                        cases[key] = _failure(scene)
                        continue
                    try:
                        cases[key] = run(ln, scene, spec, backend, extra)
                    except Exception as exc:  # noqa: BLE001 - a refusal is digested as what it is
                        cases[key] = _failure(exc)
    wall = time.perf_counter() - start
    report = {"package": str(Path(ln.__file__).parent), "library": str(library._library_path()),
              "wall_s": round(wall, 1), "cases": cases}
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(report, indent=1))
    print(f"{len(cases)} cases in {wall:.1f} s from {report['package']} ({report['library']}) -> {out_path}")
    return report


def compare(paths: list[Path]) -> tuple[str, bool]:
    """A markdown table, one row per scene x backend x kind (the methods in its columns: '=' equal digests, 'X'
    different, 'e' the same error on both sides), and whether all cases are equal."""
    reports = [json.loads(p.read_text()) for p in paths]
    base = reports[0]["cases"]
    lines = []
    all_equal = True
    for other_path, report in zip(paths[1:], reports[1:]):
        other = report["cases"]
        missing = sorted(set(base) ^ set(other))
        rows, methods = {}, []
        different = []
        for key in base:
            if key not in other:
                continue
            scene, method, backend, kind = key.split(" | ")
            if method not in methods:
                methods.append(method)
            a, b = base[key], other[key]
            same = a["XUT"] == b["XUT"] and a["other"] == b["other"]
            mark = ("e" if "error" in a else "=") if same else "X"
            if not same:
                different.append(key)
            rows.setdefault((scene, backend, kind), {})[method] = mark
        all_equal &= not different and not missing
        lines.append(f"{paths[0]} vs {other_path}: {len(base)} cases, {len(different)} different, "
                     f"{len(missing)} in one only ('=' equal digests of XUT and other, 'e' the same refusal, "
                     "'X' different)\n")
        lines.append("| scene | backend | run | " + " | ".join(methods) + " |")
        lines.append("|---|---|---|" + "---|" * len(methods))
        for (scene, backend, kind), marks in rows.items():
            lines.append(f"| {scene} | {backend} | {kind} | " + " | ".join(marks.get(m, "-") for m in methods) + " |")
        for key in different:
            lines.append(f"different: {key}: {base[key]} vs {other[key]}")
        for key in missing:
            lines.append(f"in one only: {key}")
        lines.append("")
    return "\n".join(lines), all_equal


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=None, help="digests (JSON) of the imported tree, or with --trees "
                   "the folder for each tree's digests and the table (default build/bit_identity)")
    p.add_argument("--trees", nargs="+", metavar="NAME=PATH", help="run in each tree, then compare with the first")
    p.add_argument("--compare", nargs="+", type=Path, metavar="JSON", help="compare digests written before")
    a = p.parse_args(argv)
    if a.compare:
        table, equal = compare(a.compare)
        print(table)
        return 0 if equal else 1
    if a.trees:
        # the checkout's benchmarks package, for this driver only: each tree's run imports nothing of this checkout
        sys.path.insert(0, str(REPO))
        from benchmarks.output import build_path, write_text
        folder = build_path("bit_identity", a.out, parser=p).resolve()  # the runs' working directories are the trees
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for entry in a.trees:
            name, _, tree = entry.partition("=")
            tree = str(Path(tree).resolve())
            out = folder / f"{name}.json"
            env = dict(os.environ, PYTHONPATH=tree)
            subprocess.run([sys.executable, str(Path(__file__).resolve()), "--out", str(out)], cwd=tree, env=env,
                           check=True)
            paths.append(out)
        table, equal = compare(paths)
        write_text(folder / "table.md", table)
        print(table)
        return 0 if equal else 1
    run_all(a.out or REPO / "build" / "bit_identity" / "digests.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
