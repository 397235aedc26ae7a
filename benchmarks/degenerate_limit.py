"""Do the degenerate nets (models/degenerate/) have a rigid-link motion with bounded tensions? The stiff-spring limit.

Every rigid link of the scene is replaced by a spring of stiffness k (N/m) and natural length R_l, and the spring
net is integrated (native core, dop853 at rtol 1e-11) for k = 1e7 .. 1e11. As k grows, a scene whose rigid model
has an answer converges to it: positions with gaps between successive k falling like 1/k, stretches like 1/k, and
tensions k * stretch bounded. Where the rigid model has no bounded-tension answer, the tensions of the links the
rigidity analysis names grow with k without bound while the positions may still converge: the compliant structure
takes a stretch set by the geometry, not by the load (the tilted tower's top square), or a sag that shrinks slower
than 1/k (a taut string between anchors). The rigid scene's own run is listed beside it: where it stops, and why.

    python3 -m benchmarks.degenerate_limit [--t-end 0.3] [--stiffness 1e7 1e8 1e9 1e10 1e11] [--out DIR] [--merge]

Writes build/degenerate_limit/degenerate_limit.md (the tracked docs/benchmarks/degenerate_limit.md with --merge).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import linknet_core as ln
from linknet_core.scene.builders import degenerate_scenes
from linknet_core.structure.rigidity import second_order_rigid_flexes

from .output import add_output_arguments, resolve, write_text


def spring_version(scene: ln.Scene, k: float) -> ln.Scene:
    """The scene with every rigid link a spring of stiffness k at its length R_l (no damping)."""
    d = scene.to_dict()
    d["springs"] = [{"a": link["a"], "b": link["b"], "stiffness": k, "rest_length": float(R)}
                    for link, R in zip(d["links"], scene.length)]
    d["links"] = []
    d["name"] = f"{scene.name}_springs"
    return ln.Scene.from_dict(d)


def rigid_outcome(scene: ln.Scene, t_end: float) -> str:
    """The rigid scene's default run: where it ends or why it stops (first sentence of the message)."""
    try:
        ln.simulate(scene, t_end, error_estimate=False)
        return f"runs to {t_end} s"
    except ln.LinknetError as error:
        text = str(error)
        return text[: text.find(". ") + 1] if ". " in text else text


def study(scene: ln.Scene, stiffnesses, t_end: float, n_out: int = 31):
    named = sorted({int(l) for f in second_order_rigid_flexes(scene) for l in f.links}) or list(range(scene.L))
    rows, previous = [], None
    for k in stiffnesses:
        started = time.process_time()
        result = ln.simulate(spring_version(scene, k), t_end, method="dop853", rtol=1e-11, n_out=n_out,
                             error_estimate=False)
        cpu = time.process_time() - started
        d = np.linalg.norm(result.X[:, scene.k2] - result.X[:, scene.k1], axis=2)
        stretch = d / scene.length - 1.0
        tension = k * (d - scene.length)
        late = result.t >= 0.5 * t_end  # the second half: the ringing of the release has spread
        rows.append(dict(k=k, cpu=cpu,
                         stretch=float(np.abs(stretch).max()),
                         tension=float(np.abs(tension[:, named]).max()),
                         mean_tension=float(np.abs(tension[late][:, named].mean(axis=0)).max()),
                         gap=float(np.abs(result.X - previous).max()) if previous is not None else float("nan")))
        previous = result.X
    return named, rows


def growth(rows, key):
    """The least-squares slope of log(key) against log(k) over every stiffness: the power of k it grows with."""
    k = np.log([r["k"] for r in rows])
    v = np.log([r[key] for r in rows])
    return float(np.polyfit(k, v, 1)[0])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.3)
    parser.add_argument("--stiffness", type=float, nargs="+", default=[1e7, 1e8, 1e9, 1e10, 1e11])
    add_output_arguments(parser, "degenerate_limit")
    a = parser.parse_args(argv)
    out = resolve(parser, a, "degenerate_limit") / "degenerate_limit.md"
    lines = ["# The degenerate nets' stiff-spring limit", "",
             f"`python3 -m benchmarks.degenerate_limit --t-end {a.t_end} --stiffness "
             f"{' '.join(f'{k:g}' for k in a.stiffness)}`: every link a spring of stiffness k, dop853 rtol 1e-11, "
             f"to t = {a.t_end} s, 31 samples. `tension`: the largest |k (d - R)| over the samples on the links the "
             "rigidity analysis names at the start (all links where it names none); `mean tension`: the largest "
             "over those links of |the mean over the second half|; `gap`: the largest position difference from the "
             "run at the previous k; CPU seconds of the spring run.", ""]
    for name, scene in degenerate_scenes().items():
        named, rows = study(scene, a.stiffness, a.t_end)
        lines += [f"## {name}", "", f"The rigid scene, default settings: {rigid_outcome(scene, a.t_end)}", "",
                  f"Links named: {', '.join(str(l + 1) for l in named)}", "",
                  "| k (N/m) | largest stretch | tension (N) | mean tension (N) | gap to previous k (m) | CPU (s) |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {r['k']:.0e} | {r['stretch']:.3g} | {r['tension']:.4g} | {r['mean_tension']:.4g} | "
                  f"{r['gap']:.2g} | {r['cpu']:.2f} |" for r in rows]
        gaps = [r["gap"] for r in rows[1:]]
        lines += ["", f"Fitted over k = {rows[0]['k']:.0e} .. {rows[-1]['k']:.0e}: tension ~ k^{growth(rows, 'tension'):.2f}, "
                      f"largest stretch ~ k^{growth(rows, 'stretch'):.2f}; the gap to the previous k went "
                      f"{' -> '.join(f'{g:.1g}' for g in gaps)} m. A rigid answer with bounded tensions shows tension ~ "
                      "k^0, stretch ~ k^-1 and gaps falling ~10x per decade.", ""]
        print("\n".join(lines[-(len(rows) + 8):]), flush=True)
    write_text(out, "\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
