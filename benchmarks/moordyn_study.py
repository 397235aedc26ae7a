"""MoorDyn's elastic lines against linknet's rigid rope on the rope scene, at several times of the run.

    python -m benchmarks.moordyn_study                 # writes build/moordyn_study/rope_peer.json, prints the tables
    python -m benchmarks.moordyn_study --merge         # into the tracked docs/benchmarks/rope_peer.json
    python -m benchmarks.moordyn_study --out /tmp/x --budget 10

The work-precision benchmark compares the state at t_end only. Here every run is sampled at times that separate
the errors of an elastic line (benchmarks/peers/moordyn_peer.py):

* 0.4 s: the rope taut throughout (a pendulum): the model's error is the stretch, ~1/EA;
* 0.9 s: after the slack event and a free flight;
* 1.2 s: after two jerks, each of which lasts pi sqrt(m R / EA) on the line: ~1/sqrt(EA);
* 2.0 s: after five jerks (the benchmark's t_end), where the flights amplify what came before.

For each stiffness EA, MoorDyn's step is halved from its stability limit until the error at 2 s levels off (three
halvings gain less than a factor 2) or a run would pass the budget; linknet's methods sweep their knob. Times are
CPU seconds of this one process (time.process_time: the machine's cores are shared, its wall clock is not the
run's), of the integration only (MoorDyn's Step calls, linknet's Simulator.advance), summed up to each sample
time. The references are benchmarks.rope_reference's at each sample time (two tolerances, their agreement stored).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    __package__ = "benchmarks"

from .output import add_output_arguments, resolve, write_text  # noqa: E402
from .peers.moordyn_peer import MoorDynLine, moordyn_available  # noqa: E402
from .rope_reference import solve_ropes  # noqa: E402

SCENE = "rope_swing"
TIMES = (0.4, 0.9, 1.2, 2.0)
GRID = 0.1   # the sample times are multiples of it
EAS = (1e4, 1e6, 1e8, 1e10, 1e12)
LINKNET = {"dop853": [10.0 ** -e for e in range(3, 13)], "dopri5": [10.0 ** -e for e in range(3, 11)],
           "rattle": [0.01 / 2 ** i for i in range(0, 9)], "yoshida8": [0.04 / 2 ** i for i in range(0, 5)]}
LEVELS = (1e-2, 1e-3, 1e-4, 1e-6, 1e-9)


def references(spec):
    out = []
    for t in TIMES:
        X = solve_ropes(spec, t, 2.5e-14)[0]
        Xc = solve_ropes(spec, t, 1e-13)[0]
        out.append((X, float(np.abs(X - Xc).max())))
    return out


def errors(Xs, refs):
    return [float(np.max(np.linalg.norm(X - R[0], axis=1))) for X, R in zip(Xs, refs)]


def moordyn_rows(spec, refs, budget, log):
    rows = []
    for EA in EAS:
        line = MoorDynLine(EA)
        line.check_scene(spec)
        last, finals = None, []
        for dt in line.knobs(spec, quick=False):
            dt = GRID / math.ceil(GRID / dt - 1e-9)   # a whole number of steps between the sample times
            if last is not None and 2.0 * last > budget:
                log(f"  MoorDyn EA {EA:.0e}: dt {dt:.3g} s not run (predicted {2 * last:.3g} s > budget {budget:g} s)")
                break
            Xs, cpu = line.trajectory(spec, TIMES, dt)
            err = errors(Xs, refs)
            rows.append({"method": line.name, "EA": EA, "dt": dt, "errors": err, "cpu": cpu.tolist()})
            log(f"  {line.name:22s} dt {dt:9.3g}  errors " + " ".join(f"{e:9.2e}" for e in err)
                + f"  cpu {cpu[-1]:.3g} s")
            last = float(cpu[-1])
            finals.append(err[-1])
            if len(finals) >= 4 and min(finals[-3:]) > 0.5 * min(finals[:-3]):
                break
    return rows


def linknet_rows(spec, refs, budget, log):
    import linknet_core as ln
    scene = ln.Scene.from_dict(spec.to_dict())
    rows = []
    for method, knobs in LINKNET.items():
        knob_name = "rtol" if method.startswith("dop") else "dt"
        last = None
        for knob in knobs:
            if last is not None and 2.5 * last > budget:
                log(f"  linknet-{method}: {knob_name} {knob:.3g} not run (predicted > budget {budget:g} s)")
                break
            kwargs = {knob_name: knob, "error_estimate": False, "max_steps_per_call": 10 ** 9}
            ln.Simulator(scene, method=method, **kwargs).advance(1e-3)   # warm-up: one-time set-up is not the run
            sim = ln.Simulator(scene, method=method, **kwargs)
            Xs, cpu, spent = [], [], 0.0
            for t in TIMES:
                start = time.process_time()
                sim.advance(t)
                spent += time.process_time() - start
                Xs.append(sim.state.X.copy())
                cpu.append(spent)
            err = errors(Xs, refs)
            rows.append({"method": f"linknet-{method}", knob_name: knob, "errors": err, "cpu": cpu})
            log(f"  linknet-{method:14s} {knob_name} {knob:9.3g}  errors " + " ".join(f"{e:9.2e}" for e in err)
                + f"  cpu {cpu[-1]:.3g} s")
            last = cpu[-1]
            if err[-1] < 1e-11:
                break
    return rows


def native_rod_rows(spec, refs, log, repeats=5):
    """linknet's native core on the same bob held by a rod, up to the first sample time only, where the rope is
    still taut (its slack event comes later): the same motion, so the same reference; what the engine that does
    not take ropes yet costs on it. Best of ``repeats`` (the runs take microseconds)."""
    import linknet_core as ln
    from .rope_reference import RopeReference
    first = RopeReference(spec, 1e-13)
    first.run(TIMES[0])
    if first.events:
        raise RuntimeError(f"{SCENE}: an event at {first.events[0][0]:g} s, before {TIMES[0]:g} s: not a rod there")
    data = spec.to_dict()
    for link in data["links"]:
        link.pop("kind", None), link.pop("restitution", None)
    scene = ln.Scene.from_dict(data)
    rows = []
    for method, knobs in LINKNET.items():
        knob_name = "rtol" if method.startswith("dop") else "dt"
        for knob in knobs:
            kwargs = {knob_name: knob, "error_estimate": False, "max_steps_per_call": 10 ** 9, "backend": "native"}
            ln.Simulator(scene, method=method, **kwargs).advance(1e-3)
            best = None
            for _ in range(repeats):
                sim = ln.Simulator(scene, method=method, **kwargs)
                start = time.process_time()
                sim.advance(TIMES[0])
                spent = time.process_time() - start
                best = spent if best is None else min(best, spent)
            err = float(np.max(np.linalg.norm(sim.state.X - refs[0][0], axis=1)))
            rows.append({"method": f"linknet-native-rod-{method}", knob_name: knob, "errors": [err], "cpu": [best]})
            log(f"  linknet-native-rod-{method:9s} {knob_name} {knob:9.3g}  error at {TIMES[0]:g} s {err:9.2e}  "
                f"cpu {best * 1e6:.3g} us")
            if err < 1e-11:
                break
    return rows


def slack_damping(log, span=0.1):
    """Two 1 kg masses on a slack 1 m line, 0.5 m apart and approaching at 2 m/s: MoorDyn's internal damping BA
    acts on a slack segment too (its force BA (dl/dt) / l), so their approach decays as exp(-2 BA t / (m l)) where a
    rope would leave them free. Gravity moves both alike."""
    from .scene_spec import SceneSpec
    from .peers.moordyn_peer import _Session
    spec = SceneSpec.from_dict({
        "name": "slack_line", "gravity": [0, 0, -9.81],
        "masses": [{"name": "a", "position": [0, 0, 0], "mass": 1.0, "velocity": [1.0, 0, 0]},
                   {"name": "b", "position": [0.5, 0, 0], "mass": 1.0, "velocity": [-1.0, 0, 0]}],
        "links": [{"a": 1, "b": 2, "length": 1.0, "kind": "rope", "restitution": 1.0}]})
    rows = []
    for BA in (0.0, 1.0, 10.0):
        session = _Session(MoorDynLine(1e6, damping=BA), spec, 1e-4)
        try:
            X, U = session.step(0.0, span)
        finally:
            session.close()
        approach = float(U[0, 0] - U[1, 0])
        rows.append({"BA": BA, "approach_speed": approach, "exp(-2 BA t / (m l)) x 2": 2 * math.exp(-2 * BA * span)})
        log(f"  slack line, BA {BA:g} N s: approach speed after {span:g} s {approach:.6f} m/s "
            f"(2 exp(-2 BA t / (m l)) = {2 * math.exp(-2 * BA * span):.6f}; a rope: 2)")
    return rows


def frontier(rows, family, times=TIMES):
    """Per sample time and level: the cheapest run of the family whose error there is at or below the level."""
    out = {}
    for i, t in enumerate(times):
        for level in LEVELS:
            ok = [r for r in rows if r["method"].startswith(family) and r["errors"][i] <= level]
            best = min(ok, key=lambda r: r["cpu"][i]) if ok else None
            out[f"{t:g}/{level:g}"] = None if best is None else {
                "method": best["method"], "cpu": best["cpu"][i], "error": best["errors"][i],
                **{k: best[k] for k in ("EA", "dt", "rtol") if k in best}}
    return out


def _cell(b):
    if b is None:
        return "—"
    if "EA" in b:
        knob = f"EA {b['EA']:.0e}, dt {b['dt']:.2g}"
    else:
        name = b["method"].removeprefix("linknet-").removeprefix("native-rod-")
        knob = f"{name} " + (f"rtol {b['rtol']:.0e}" if "rtol" in b else f"dt {b['dt']:.2g}")
    return f"{b['cpu'] * 1e3:.3g} ms ({knob})"


def markdown(result) -> str:
    lines = ["| t [s] | level [m] | MoorDyn: CPU (setting) | linknet, numpy path, rope: CPU (setting) | "
             "MoorDyn / linknet | linknet native, rod: CPU (setting) |", "|---|---|---|---|---|---|"]
    for t in TIMES:
        for level in LEVELS:
            key = f"{t:g}/{level:g}"
            m, l = result["frontier"]["moordyn"][key], result["frontier"]["linknet"][key]
            native = result["frontier"]["native_rod"].get(key)
            ratio = f"{m['cpu'] / l['cpu']:.3g}" if m and l and l["cpu"] > 0 else "—"
            lines.append(f"| {t:g} | {level:g} | {_cell(m)} | {_cell(l)} | {ratio} | "
                         f"{_cell(native) if t == TIMES[0] else 'n/a (slack after 0.495 s)'} |")
    lines += ["", "Best error of each MoorDyn stiffness (any step) at each sample time:", "",
              "| EA [N] | " + " | ".join(f"t = {t:g} s" for t in TIMES) + " |", "|---|" + "---|" * len(TIMES)]
    for EA in EAS:
        rs = [r for r in result["moordyn"] if r["EA"] == EA]
        if rs:
            lines.append(f"| {EA:.0e} | " + " | ".join(f"{min(r['errors'][i] for r in rs):.2e}"
                                                      for i in range(len(TIMES))) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_output_arguments(ap, "moordyn_study")
    ap.add_argument("--budget", type=float, default=30.0, help="CPU seconds one run may take (predicted)")
    args = ap.parse_args(argv)
    out = resolve(ap, args, "moordyn_study") / "rope_peer.json"
    ok, why = moordyn_available()
    if not ok:
        print(f"MoorDyn unavailable: {why}")
        return None
    from .work_precision import _loadavg, _machine, _versions, load_benchmark_scene
    spec = load_benchmark_scene(SCENE)
    load_start = _loadavg()
    refs = references(spec)
    print(f"{SCENE}: reference agreement at {', '.join(f'{t:g}' for t in TIMES)} s: "
          + ", ".join(f"{a:.2g}" for _, a in refs) + " m")
    md = moordyn_rows(spec, refs, args.budget, print)
    lk = linknet_rows(spec, refs, args.budget, print)
    native = native_rod_rows(spec, refs, print)
    damping = slack_damping(print)
    import moordyn
    result = {"scene": SCENE, "times": TIMES, "levels": LEVELS, "reference_agreement": [a for _, a in refs],
              "moordyn": md, "linknet": lk, "native_rod": native, "slack_damping": damping,
              "frontier": {"moordyn": frontier(md, "moordyn"), "linknet": frontier(lk, "linknet-"),
                           "native_rod": frontier(native, "linknet-native-rod", TIMES[:1])},
              "meta": {"command": "python -m benchmarks.moordyn_study " + " ".join(argv or sys.argv[1:]),
                       "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "machine": _machine(),
                       "versions": _versions() | {"moordyn_wrapper": getattr(moordyn, "__version__", None)},
                       "load_average": {"start": load_start, "end": _loadavg()}, "timing": "CPU (process_time)"}}
    write_text(out, json.dumps(result, indent=1))
    print(markdown(result))
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
