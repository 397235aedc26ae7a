"""Accurate by default, measured: scene x method -> the error at t_end against the independent index-1 reference
(benchmarks.reference, scipy's DOP853 on the seed's (9), (25)-(26)), the run's own error estimate there
(linknet_core.accuracy: its companion run), the goal, and the time with and without the estimate.

    python -m benchmarks.accuracy [--quick] [--scenes NAME ...] [--out FILE.md]    # prints the table (and writes FILE.md)

Every shipped scene runs to the t_end where its reference is verified (benchmarks.work_precision.SCENES, or the
stop time the scene's notes give), plus scenes of this script's own that no test tunes to (EXTRA). The references
are cached in docs/benchmarks/references (their digest covers every number of the scene; a tracked cache, see
benchmarks.reference). Measures; asserts nothing (tests/core/test_error_estimate.py asserts).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import linknet_core as ln
from linknet_core.accuracy import AccuracyWarning

from .output import checked, write_text
from .reference import reference
from .scene_spec import SceneSpec

ROOT = Path(__file__).resolve().parent.parent
# t_end per shipped scene: where the index-1 reference is verified to 1e-12 m (work_precision's, for the same
# reasons), and net_10x10 to 1 s too (its reference's two tolerances agree there: see docs/accuracy.md); the
# crane over its trolley's 3 s travel (the reference drives the anchor from the scene file's waypoints)
T_END = {"pendulum": 2.0, "double_pendulum": 2.0, "chain_10": 2.0, "chain_100": 1.0, "net_10x10": 1.0,
         "four_bar": 2.0, "spinning_tetrahedron": 2.0, "redundant_truss": 2.0, "braced_tower": 0.7,
         "triangulated_net": 0.5, "crane": 3.0, "rope_swing": 2.0, "rope_pendulum": 2.0}
QUICK = ("pendulum", "double_pendulum", "chain_10", "four_bar", "mass_ratio_chain")
# (label, simulate's keywords): the default first
METHODS = (("default", {}),
           ("dopri5 rtol 1e-8", {"method": "dopri5"}),
           ("dop853 rtol 1e-10", {"method": "dop853", "rtol": 1e-10}),
           ("rattle dt 1e-3", {"method": "rattle", "dt": 1e-3}),
           ("rattle dt 1e-4", {"method": "rattle", "dt": 1e-4}),
           ("yoshida4 dt 1e-3", {"method": "yoshida4", "dt": 1e-3}))


def extra_scenes() -> dict:
    """Scenes of this benchmark's own (no test tunes to them): a chain whose masses run from 0.1 to 10 kg, a
    branched tree swinging in 3-D, a small net hung from one corner and set spinning about it."""
    from linknet_core.scene import builders
    chain = builders.chain(8, total_length=1.0, shape="horizontal", name="mass_ratio_chain").to_dict()
    for i, m in enumerate(chain["masses"][1:]):
        m["mass"] = float(10.0 ** (-1 + 2 * i / 7))
    # initial velocities that satisfy (12) as they stand (a rigid rotation about the anchor), since the index-1
    # reference takes them unprojected
    def spin(entries, omega):
        origin = np.array(entries[0]["position"], float)
        for m in entries[1:]:
            m["velocity"] = np.cross(omega, np.array(m["position"], float) - origin).tolist()

    tree = {"name": "swinging_tree", "gravity": [0, 0, -9.81],
            "masses": [{"name": "root", "position": [0, 0, 0], "fixed": True},
                       {"name": "hub", "position": [0.3, 0, 0], "mass": 1.0},
                       {"name": "a", "position": [0.6, 0, 0], "mass": 0.5},
                       {"name": "b", "position": [0.3, 0.3, 0], "mass": 0.2},
                       {"name": "c", "position": [0.3, 0, 0.3], "mass": 2.0},
                       {"name": "a2", "position": [0.9, 0, 0], "mass": 0.1}],
            "links": [{"a": "root", "b": "hub"}, {"a": "hub", "b": "a"}, {"a": "hub", "b": "b"},
                      {"a": "hub", "b": "c"}, {"a": "a", "b": "a2"}]}
    spin(tree["masses"], [0.0, 0.0, 2.0])
    net = builders.net(3, 4, spacing=0.2, anchors=[(0, 0)], name="thrown_net").to_dict()
    spin(net["masses"], [1.0, -1.0, 2.0])
    return {d["name"]: (ln.Scene.from_dict(d), 1.0) for d in (chain, tree, net)}


def shipped_scenes(names=None) -> dict:
    out = {}
    # the rope scenes' references are event-driven (benchmarks.rope_reference); the rope crane's driven trolley is
    # not one of them
    for path in sorted((ROOT / "models").glob("*.json")) + sorted((ROOT / "models" / "ropes").glob("*.json")):
        name = path.stem
        if name in T_END and (names is None or name in names):
            out[name] = (ln.load_scene(path), T_END[name])
    return out


def timed(scene, t_end, kw, error_estimate, repeat):
    best, res = math.inf, None
    for _ in range(repeat):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", AccuracyWarning)
            t0 = time.perf_counter()
            res = ln.simulate(scene, t_end, n_out=11, progress=False, error_estimate=error_estimate, **kw)
            best = min(best, time.perf_counter() - t0)
    return res, best


def measure(name, scene, t_end, log=print):
    try:
        ref = reference(SceneSpec.from_core(scene), t_end, log=log)
    except RuntimeError as exc:  # the reference could not be computed: say so in the table, go on
        return [{"scene": name, "method": "(all)", "failed": f"no reference: {exc}"}]
    rows = []
    for label, kw in METHODS:
        try:
            res, with_estimate = timed(scene, t_end, kw, True, 3)
            _, without = timed(scene, t_end, kw, False, 3)
        except ln.LinknetError as exc:
            rows.append({"scene": name, "method": label, "failed": str(exc).splitlines()[0][:120]})
            continue
        error = float(np.max(np.linalg.norm(res.X[-1] - ref["X"], axis=1)))
        estimate = float(res.error_estimate[-1])
        rows.append({"scene": name, "method": label, "t_end": t_end, "error": error, "estimate": estimate,
                     "ratio": estimate / error if error > 0 else math.inf, "goal": res.error_goal,
                     "within_goal": res.max_error_estimate <= res.error_goal,
                     "reference_agreement": float(ref["agreement"]), "ms": 1e3 * without,
                     "ms_with_estimate": 1e3 * with_estimate})
    return rows


def table(rows) -> str:
    lines = ["| scene | method | t_end | error (reference) | estimate | estimate / error | goal | within goal | "
             "ms | ms with estimate |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "failed" in r:
            lines.append(f"| {r['scene']} | {r['method']} | | failed: {r['failed']} | | | | | | |")
            continue
        floor = 10 * r["reference_agreement"]
        ratio = f"{r['ratio']:.2g}" if r["error"] > floor else f"(error below the reference's floor {floor:.1g})"
        lines.append(f"| {r['scene']} | {r['method']} | {r['t_end']:g} | {r['error']:.2e} | {r['estimate']:.2e} | "
                     f"{ratio} | {r['goal']:.1e} | {'yes' if r['within_goal'] else 'NO'} | {r['ms']:.3g} | "
                     f"{r['ms_with_estimate']:.3g} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    p.add_argument("--scenes", nargs="*")
    p.add_argument("--out", help="also write the table (Markdown) to this file (not inside docs/)")
    args = p.parse_args(argv)
    out = checked(args.out, can_merge=False, parser=p) if args.out else None
    names = set(args.scenes) if args.scenes else (set(QUICK) if args.quick else None)
    scenes = shipped_scenes(names)
    scenes.update({n: v for n, v in extra_scenes().items() if names is None or n in names})
    rows = []
    for name, (scene, t_end) in scenes.items():
        print(f"[{name}] K={scene.K} L={scene.L} t_end={t_end}", flush=True)
        scene_rows = measure(name, scene, t_end)
        print("\n".join(table(scene_rows).splitlines()[2:]), flush=True)  # as measured: a long run loses nothing
        rows.extend(scene_rows)
    text = table(rows)
    print(text)
    if out:
        write_text(out, text + "\n")
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
