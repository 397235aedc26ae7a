"""MoorDyn's elastic lines against linknet's rigid ropes on the rope scenes, at several times of each run.

    python -m benchmarks.moordyn_study                 # writes build/moordyn_study/rope_peer.json, prints the tables
    python -m benchmarks.moordyn_study --merge         # into the tracked docs/benchmarks/rope_peer.json
    python -m benchmarks.moordyn_study --scene rope_chain_whip --merge   # docs/benchmarks/rope_peer_chain_whip.json
    python -m benchmarks.moordyn_study --scene rope_chain_drop --quick    # the smoke run: build/moordyn_study/quick
    python -m benchmarks.moordyn_study --scene rope_chain_seabed_landing --merge   # ..._chain_seabed_landing.json
    python -m benchmarks.moordyn_study --scene rope_chain_seabed_slide --merge     # ..._chain_seabed_slide.json
    python -m benchmarks.moordyn_study --scene rope_chain_seabed_drag --merge      # ..._chain_seabed_drag.json
    python -m benchmarks.moordyn_study --out /tmp/x --budget 10

The work-precision benchmark compares the state at t_end only. Here every run is sampled at times that separate
the errors of an elastic line (benchmarks/peers/moordyn_peer.py). rope_swing (models/ropes, one rope):

* 0.4 s: the rope taut throughout (a pendulum): the model's error is the stretch, ~1/EA;
* 0.9 s: after the slack event and a free flight;
* 1.2 s: after two jerks, each of which lasts pi sqrt(m R / EA) on the line: ~1/sqrt(EA);
* 2.0 s: after five jerks (the benchmark's t_end), where the flights amplify what came before.

rope_chain_drop (models/ropes/chains, 8 segments dropped from a slack zig-zag): 0.2 s (one jerk), 0.3 s (6), 0.5 s
(54), 1.0 s (195); every jerk of one segment with the others slack. rope_chain_whip (8 segments hanging taut, the
free end thrown): 0.1 s (the end's first flight, the rest taut: the stretch), 0.3 s (one jerk, the whole rope taut
at it), 0.6 s (2), 1.0 s (5).

The seabed scenes (models/ropes/chains, the same rope over a ground; MoorDyn's seabed through
benchmarks/peers/moordyn_seabed.py, its contact stiffness tied to EA) have every segment slack throughout, and their
reference is rope_reference.slack_rope_on_ground's closed form. rope_chain_seabed_landing (the drop's zig-zag, the
seabed 0.15 m below the anchor): 0.05 s (free fall), 0.102 s (0.96 ms after the lower nodes land), 0.176 s (1.13 ms
after the upper ones), 0.5 s (at rest: MoorDyn's error the sink m g / k). rope_chain_seabed_slide (lying on a rough
seabed, mu 0.5, thrown sideways): 0.05 and 0.1 s (sliding), 0.2 s (all stopped, the last at 0.183 s), 0.5 s.
rope_chain_seabed_drag (a zig-zag lying on the rough seabed, its end anchor driven away at 1 m/s, a MoorDyn coupled
point): its segments jerk taut along the seabed one after another, and its reference is
rope_reference.rope_dragged_on_ground's closed form, event by event: 0.1 s (one jerk), 0.2 s (2), 0.5 s (22),
1.0 s (106).

For each stiffness EA, MoorDyn's step is halved from its stability limit until the error at the last sample time
levels off (three halvings gain less than a factor 2) or a run would pass the budget; linknet's methods sweep their
knob, on the numpy reference path and on the native core where it takes the scene (the fastest of a few runs: they
take microseconds to milliseconds). Times are CPU seconds of this one process (time.process_time: the machine's
cores are shared, its wall clock is not the run's), of the integration only (MoorDyn's Step calls, linknet's
Simulator.advance), summed up to each sample time. The references are benchmarks.rope_reference's at the sample
times, in one run (two tolerances, their agreement stored).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    __package__ = "benchmarks"

from .output import add_output_arguments, resolve, write_text  # noqa: E402
from .peers.moordyn_peer import MoorDynLine, moordyn_available  # noqa: E402
from .peers.moordyn_seabed import MoorDynSeabedLine  # noqa: E402
from .rope_reference import rope_dragged_on_ground, slack_rope_on_ground, solve_ropes_at  # noqa: E402


@dataclass(frozen=True)
class Study:
    """One scene's study: where the scene is, its sample times (multiples of ``grid``, so that a MoorDyn step can
    divide them), the stiffnesses swept, the accuracy levels of the tables, and the results file."""
    scene: str
    times: tuple
    eas: tuple
    levels: tuple
    output: str
    grid: float = 0.1
    folder: str = ""            # under models/ ("" for load_benchmark_scene's places)
    native_rod: bool = False    # also the native core on the same masses held by rods, up to times[0]
    reference: str = "ropes"    # "ropes": rope_reference's event-driven run; "slack_rope": its closed form of a
                                # rope that stays slack over a ground (rope_reference.slack_rope_on_ground);
                                # "dragged_rope": that of a rope dragged on it (rope_reference.rope_dragged_on_ground)
    peer: type = MoorDynLine    # MoorDynSeabedLine where the scene has a ground


STUDIES = {s.scene: s for s in (
    Study("rope_swing", (0.4, 0.9, 1.2, 2.0), (1e4, 1e6, 1e8, 1e10, 1e12), (1e-2, 1e-3, 1e-4, 1e-6, 1e-9),
          "rope_peer.json", native_rod=True),
    Study("rope_chain_drop", (0.2, 0.3, 0.5, 1.0), (1e4, 1e6, 1e8, 1e10), (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-9),
          "rope_peer_chain_drop.json", folder="ropes/chains"),
    Study("rope_chain_whip", (0.1, 0.3, 0.6, 1.0), (1e4, 1e6, 1e8, 1e10), (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-9),
          "rope_peer_chain_whip.json", folder="ropes/chains"),
    Study("rope_chain_seabed_landing", (0.05, 0.102, 0.176, 0.5), (1e4, 1e6, 1e8, 1e10),
          (1e-2, 1e-3, 1e-4, 1e-6, 1e-9), "rope_peer_chain_seabed_landing.json", grid=0.001, folder="ropes/chains",
          reference="slack_rope", peer=MoorDynSeabedLine),
    Study("rope_chain_seabed_slide", (0.05, 0.1, 0.2, 0.5), (1e4, 1e6, 1e8, 1e10), (1e-2, 1e-3, 1e-4, 1e-6, 1e-9),
          "rope_peer_chain_seabed_slide.json", folder="ropes/chains", reference="slack_rope", peer=MoorDynSeabedLine),
    Study("rope_chain_seabed_drag", (0.1, 0.2, 0.5, 1.0), (1e4, 1e6, 1e8, 1e10), (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-9),
          "rope_peer_chain_seabed_drag.json", folder="ropes/chains", reference="dragged_rope",
          peer=MoorDynSeabedLine),
)}
LINKNET = {"dop853": [10.0 ** -e for e in range(3, 13)], "dopri5": [10.0 ** -e for e in range(3, 11)],
           "rattle": [0.01 / 2 ** i for i in range(0, 9)], "yoshida8": [0.04 / 2 ** i for i in range(0, 5)]}
BACKENDS = {"numpy": 1, "native": 5}   # linknet's two engines, and the runs of which the fastest counts
QUICK_EA = 1e6                          # the smoke run's one stiffness
QUICK_KNOBS = 1                         # and each linknet method's first setting
QUICK_TIMES = 2                         # to the first two sample times


def load_scene(study):
    from .work_precision import MODELS, load_benchmark_scene
    if not study.folder:
        return load_benchmark_scene(study.scene)
    import linknet_core as ln
    from .scene_spec import SceneSpec
    return SceneSpec.from_core(ln.load_scene(MODELS / study.folder / f"{study.scene}.json"))


def references(spec, times, kind="ropes"):
    """The reference positions at the times and how far they are from a second determination: the event-driven
    reference at rtol 2.5e-14 against 1e-13 ("ropes"), or a closed form, exact to round-off (0): of a slack rope on
    a ground ("slack_rope") or of a rope dragged on a rough ground ("dragged_rope")."""
    if kind == "ropes":
        fine, _ = solve_ropes_at(spec, times, 2.5e-14)
        coarse, _ = solve_ropes_at(spec, times, 1e-13)
    elif kind == "slack_rope":
        fine = coarse = slack_rope_on_ground(spec, times)[0]
    elif kind == "dragged_rope":
        fine = coarse = rope_dragged_on_ground(spec, times)[0]
    else:
        raise ValueError(f"reference {kind!r}: one of 'ropes', 'slack_rope', 'dragged_rope'")
    return [(X, float(np.abs(X - Xc).max())) for X, Xc in zip(fine, coarse)]


def errors(Xs, refs):
    return [float(np.max(np.linalg.norm(X - R[0], axis=1))) for X, R in zip(Xs, refs)]


def whole_steps(grid: float, dt: float) -> float:
    """The longest step not over dt that makes a whole number of steps between sample times grid apart."""
    return grid / math.ceil(grid / dt - 1e-9)


def moordyn_rows(spec, refs, budget, log, study, quick=False):
    rows = []
    for EA in (QUICK_EA,) if quick else study.eas:
        line = study.peer(EA)
        line.check_scene(spec)
        last, finals = None, []
        for dt in line.knobs(spec, quick=quick):
            dt = whole_steps(study.grid, dt)
            if last is not None and 2.0 * last > budget:
                log(f"  MoorDyn EA {EA:.0e}: dt {dt:.3g} s not run (predicted {2 * last:.3g} s > budget {budget:g} s)")
                break
            Xs, cpu = line.trajectory(spec, study.times, dt)
            err = errors(Xs, refs)
            rows.append({"method": line.name, "EA": EA, "dt": dt, "errors": err, "cpu": cpu.tolist(),
                         "X": np.asarray(Xs).tolist(), **seabed_settings(line, spec)})
            log(f"  {line.name:22s} dt {dt:9.3g}  errors " + " ".join(f"{e:9.2e}" for e in err)
                + f"  cpu {cpu[-1]:.3g} s")
            last = float(cpu[-1])
            finals.append(err[-1])
            if len(finals) >= 4 and min(finals[-3:]) > 0.5 * min(finals[:-3]):
                break
    return rows


def seabed_settings(line, spec):
    """The seabed's options of a MoorDynSeabedLine run (kb, cb, FricDamp, mu), none for a line alone."""
    if not isinstance(line, MoorDynSeabedLine):
        return {}
    return {k: v for k, v in line.seabed(spec).items() if k in ("kb", "cb", "FricDamp", "mu")}


def linknet_rows(spec, refs, budget, log, times, quick=False):
    """linknet's methods over their knobs, on each backend that takes the scene: errors at the times and the CPU
    seconds of Simulator.advance summed to each (the fastest of BACKENDS[backend] runs)."""
    import linknet_core as ln
    scene = ln.Scene.from_dict(spec.to_dict())
    rows = []
    for backend, repeats in BACKENDS.items():
        for method, knobs in LINKNET.items():
            knob_name = "rtol" if method.startswith("dop") else "dt"
            last = None
            for knob in knobs[:QUICK_KNOBS] if quick else knobs:
                if last is not None and 2.5 * last > budget:
                    log(f"  linknet-{backend}-{method}: {knob_name} {knob:.3g} not run "
                        f"(predicted > budget {budget:g} s)")
                    break
                kwargs = {knob_name: knob, "error_estimate": False, "max_steps_per_call": 10 ** 9, "backend": backend}
                try:   # warm-up: one-time set-up is not the run
                    ln.Simulator(scene, method=method, **kwargs).advance(1e-3)
                except ln.SolverError as e:
                    log(f"  linknet-{backend}-{method}: refused ({e})")
                    break
                best = None
                for _ in range(repeats):
                    sim = ln.Simulator(scene, method=method, **kwargs)
                    Xs, cpu, spent = [], [], 0.0
                    for t in times:
                        start = time.process_time()
                        sim.advance(t)
                        spent += time.process_time() - start
                        Xs.append(sim.state.X.copy())
                        cpu.append(spent)
                    if best is None or cpu[-1] < best[1][-1]:
                        best = (Xs, cpu)
                Xs, cpu = best
                err = errors(Xs, refs)
                rows.append({"method": f"linknet-{backend}-{method}", "backend": backend, knob_name: knob,
                             "errors": err, "cpu": cpu})
                log(f"  linknet-{backend}-{method:8s} {knob_name} {knob:9.3g}  errors "
                    + " ".join(f"{e:9.2e}" for e in err) + f"  cpu {cpu[-1] * 1e3:.3g} ms")
                last = cpu[-1]
                if err[-1] < 1e-11:
                    break
    return rows


def native_rod_rows(spec, refs, log, times, repeats=5):
    """linknet's native core on the same masses held by rods, up to the first sample time only, where the ropes are
    still taut (their first event comes later): the same motion, so the same reference. Best of ``repeats`` (the
    runs take microseconds)."""
    import linknet_core as ln
    from .rope_reference import RopeReference
    first = RopeReference(spec, 1e-13)
    first.run(times[0])
    if first.events:
        raise RuntimeError(f"{spec.name}: an event at {first.events[0][0]:g} s, before {times[0]:g} s: not a rod there")
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
                sim.advance(times[0])
                spent = time.process_time() - start
                best = spent if best is None else min(best, spent)
            err = float(np.max(np.linalg.norm(sim.state.X - refs[0][0], axis=1)))
            rows.append({"method": f"linknet-native-rod-{method}", knob_name: knob, "errors": [err], "cpu": [best]})
            log(f"  linknet-native-rod-{method:9s} {knob_name} {knob:9.3g}  error at {times[0]:g} s {err:9.2e}  "
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


def stiffness_convergence(rows):
    """The distance between the finest runs of successive stiffnesses at each sample time: where it falls far below
    their errors, the lines converge as EA grows, to a limit the rigid reference is not (the error at the largest
    stiffness, less this distance, is the gap between the two limits)."""
    finest = {}
    for r in rows:
        if r["EA"] not in finest or r["dt"] < finest[r["EA"]]["dt"]:
            finest[r["EA"]] = r
    eas = sorted(finest)
    return [{"EA": a, "EA_next": b, "dt": finest[a]["dt"], "dt_next": finest[b]["dt"],
             "distance": [float(np.max(np.linalg.norm(np.subtract(Xa, Xb), axis=1)))
                          for Xa, Xb in zip(finest[a]["X"], finest[b]["X"])]}
            for a, b in zip(eas, eas[1:])]


def frontier(rows, family, times, levels):
    """Per sample time and level: the cheapest run of the family whose error there is at or below the level."""
    out = {}
    for i, t in enumerate(times):
        for level in levels:
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
        name = b["method"].split("-")[-1]
        knob = f"{name} " + (f"rtol {b['rtol']:.0e}" if "rtol" in b else f"dt {b['dt']:.2g}")
    return f"{b['cpu'] * 1e3:.3g} ms ({knob})"


def _ratio(a, b):
    return f"{a['cpu'] / b['cpu']:.3g}" if a and b and b["cpu"] > 0 else "—"


def markdown(result) -> str:
    times, levels, fr = result["times"], result["levels"], result["frontier"]
    native_rod = "native_rod" in fr
    lines = ["| t [s] | level [m] | MoorDyn: CPU (setting) | linknet numpy path: CPU (setting) | MoorDyn / numpy | "
             "linknet native core: CPU (setting) | MoorDyn / native |"
             + (" linknet native, rod: CPU (setting) |" if native_rod else ""),
             "|---|---|---|---|---|---|---|" + ("---|" if native_rod else "")]
    for t in times:
        for level in levels:
            key = f"{t:g}/{level:g}"
            m, n, c = fr["moordyn"][key], fr["linknet-numpy"][key], fr["linknet-native"][key]
            row = f"| {t:g} | {level:g} | {_cell(m)} | {_cell(n)} | {_ratio(m, n)} | {_cell(c)} | {_ratio(m, c)} |"
            if native_rod:
                row += f" {_cell(fr['native_rod'][key]) if key in fr['native_rod'] else 'n/a (slack later)'} |"
            lines.append(row)
    lines += ["", "Best error of each MoorDyn stiffness (any step) at each sample time:", "",
              "| EA [N] | " + " | ".join(f"t = {t:g} s" for t in times) + " |", "|---|" + "---|" * len(times)]
    for EA in sorted({r["EA"] for r in result["moordyn"]}):
        rs = [r for r in result["moordyn"] if r["EA"] == EA]
        lines.append(f"| {EA:.0e} | " + " | ".join(f"{min(r['errors'][i] for r in rs):.2e}"
                                                  for i in range(len(times))) + " |")
    if result.get("stiffness_convergence"):
        lines += ["", "Distance between the finest MoorDyn runs of successive stiffnesses:", "",
                  "| EA [N] | " + " | ".join(f"t = {t:g} s" for t in times) + " |", "|---|" + "---|" * len(times)]
        for c in result["stiffness_convergence"]:
            lines.append(f"| {c['EA']:.0e} (dt {c['dt']:.3g}) to {c['EA_next']:.0e} (dt {c['dt_next']:.3g}) | "
                         + " | ".join(f"{d:.2e}" for d in c["distance"]) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_output_arguments(ap, "moordyn_study", quick=True)
    ap.add_argument("--scene", choices=sorted(STUDIES), default="rope_swing", help="the scene studied")
    ap.add_argument("--budget", type=float, default=30.0, help="CPU seconds one run may take (predicted)")
    ap.add_argument("--quick", action="store_true",
                    help=f"smoke run: the first {QUICK_TIMES} sample times, MoorDyn at EA {QUICK_EA:.0e} N only and "
                         f"three steps, linknet's first setting of each method, no rods (writes under "
                         "build/moordyn_study/quick)")
    args = ap.parse_args(argv)
    study = STUDIES[args.scene]
    out = resolve(ap, args, "moordyn_study", quick=args.quick) / study.output
    ok, why = moordyn_available()
    if not ok:
        print(f"MoorDyn unavailable: {why}")
        return None
    from .work_precision import _loadavg, _machine, _versions
    spec = load_scene(study)
    times = list(study.times[:QUICK_TIMES] if args.quick else study.times)
    load_start = _loadavg()
    refs = references(spec, times, study.reference)
    print(f"{study.scene}: reference agreement at {', '.join(f'{t:g}' for t in times)} s: "
          + ", ".join(f"{a:.2g}" for _, a in refs) + " m")
    md = moordyn_rows(spec, refs, args.budget, print, study, quick=args.quick)
    lk = linknet_rows(spec, refs, args.budget, print, times, quick=args.quick)
    result = {"scene": study.scene, "times": times, "levels": list(study.levels), "quick": args.quick,
              "reference_agreement": [a for _, a in refs], "moordyn": md, "linknet": lk,
              "stiffness_convergence": stiffness_convergence(md),
              "frontier": {"moordyn": frontier(md, "moordyn", times, study.levels),
                           **{f"linknet-{b}": frontier(lk, f"linknet-{b}-", times, study.levels) for b in BACKENDS}}}
    if study.native_rod and not args.quick:
        result["native_rod"] = native_rod_rows(spec, refs, print, times)
        result["frontier"]["native_rod"] = frontier(result["native_rod"], "linknet-native-rod", times[:1],
                                                    study.levels)
    if study.scene == "rope_swing" and not args.quick:
        result["slack_damping"] = slack_damping(print)
    import moordyn
    command = "python -m benchmarks.moordyn_study " + " ".join(sys.argv[1:] if argv is None else argv)
    result["meta"] = {"command": command,
                      "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "machine": _machine(),
                      "versions": _versions() | {"moordyn_wrapper": getattr(moordyn, "__version__", None)},
                      "load_average": {"start": load_start, "end": _loadavg()}, "timing": "CPU (process_time)"}
    write_text(out, json.dumps(result, indent=1))
    print(markdown(result))
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
