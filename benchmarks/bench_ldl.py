"""The native sparse LDL^T of the tension matrix A (25) on its own: analysis, fill, factorisation and solves.

A RATTLE step of a general scene does one numeric factorisation of A and a few solves with it (the 100 x 100
net: 1 and 2, counted on the native core's calls), so the table gives factor, solve and factor + 6 solves
(the upper end of 3-8 solves per step). Scenes: a 100 x 100 net (10000 masses, 19800 links) in AMD's order
(what linknet_core.structure.topology chooses) and in the order chosen before AMD (SuperLU's multiple minimum degree on
A + A^T or reverse Cuthill-McKee, whichever fills less, reproduced here), models/net_10x10.json,
models/chain_100.json and a binary tree hanging from one anchor (both leaves-first, no fill). A's entries are
those of a random configuration near the initial one. Times are the best of several repeats of CPU time of
this thread (the machine may be shared); analysis is timed once.

``--step`` also times whole RATTLE steps (dt 1e-4 s) of the 100 x 100 net through linknet_core.Simulator on
the native core, against factor + 2 solves.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_ldl [--step] [--repeats 15] [--portable]
"""
from __future__ import annotations

import argparse
import ctypes
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from linknet_core.scene import builders
from linknet_core.clib.ldl import NativeLDL, vector_kernels
from linknet_core.scene.description import Scene, load_scene
from linknet_core.structure.topology import analyse, link_pairs

MODELS = Path(__file__).resolve().parent.parent / "models"


def pair_values(scene: Scene, X: np.ndarray):
    pairs = link_pairs(scene)
    E = (X[scene.k2] - X[scene.k1]) / scene.length[:, None]
    return pairs.first, pairs.second, pairs.sign * scene.inv_mass[pairs.mass] * np.einsum(
        "ij,ij->i", E[pairs.first], E[pairs.second])


def previous_ordering(L: int, first, second, lib=None) -> np.ndarray:
    """The general-graph ordering before AMD: SuperLU's MMD on A + A^T (and its inverse) or RCM, least fill."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    from scipy.sparse.linalg import splu

    pattern = sp.coo_matrix((np.ones(first.size), (first, second)), shape=(L, L)).tocsr()
    pattern = ((pattern + pattern.T) != 0).astype(float)
    candidates = [np.asarray(reverse_cuthill_mckee(pattern, symmetric_mode=True), np.int64)]
    lu = splu(pattern.tocsc() + sp.identity(L, format="csc") * L, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    candidates += [np.asarray(lu.perm_c, np.int64), np.argsort(lu.perm_c).astype(np.int64)]
    fills = [NativeLDL(L, first, second, order, lib).nnz_L for order in candidates]
    return candidates[int(np.argmin(fills))]


def hanging_tree(depth: int) -> Scene:
    masses = [{"name": "root", "position": [0.0, 0.0, 0.0], "fixed": True}]
    links, level = [], [0]
    for d in range(1, depth + 1):
        nxt = []
        for parent in level:
            for side in (-1, 1):
                x = masses[parent]["position"][0] + side * 2.0 ** -d
                masses.append({"name": f"m{len(masses)}", "position": [x, 0.0, -float(d)], "mass": 1.0})
                links.append({"a": parent + 1, "b": len(masses), "length": float(np.hypot(2.0 ** -d, 1.0))})
                nxt.append(len(masses) - 1)
        level = nxt
    return Scene.from_dict({"name": f"tree_{len(links)}", "masses": masses, "links": links})


def best_time(function, repeats: int, inner: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.thread_time()
        for _ in range(inner):
            function()
        best = min(best, (time.thread_time() - start) / inner)
    return best


def measure(name: str, scene: Scene, ordering, repeats: int, lib=None) -> dict:
    rng = np.random.default_rng(0)
    X = scene.X0 + 0.02 * scene.length.mean() * rng.standard_normal(scene.X0.shape)
    first, second, values = pair_values(scene, X)
    start = time.perf_counter()
    ldl = NativeLDL(scene.L, first, second, ordering, lib)
    analyse_s = time.perf_counter() - start
    b = rng.standard_normal(scene.L)
    x = np.empty_like(b)
    # the raw calls, as the stage code makes them (no Python checks in the timed loop)
    f, s = ldl._lib.ln_ldl_factor, ldl._lib.ln_ldl_solve
    pv = values.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
    pb, px = b.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
    assert f(ldl._symbolic, ldl._numeric, pv, 1e-11) == -1
    s(ldl._symbolic, ldl._numeric, pb, px)
    A = sp.coo_matrix((values, (first, second)), shape=(scene.L, scene.L)).tocsr()
    A = A + A.T - sp.diags(A.diagonal())
    residual = np.linalg.norm(A @ x - b) / np.linalg.norm(b)
    inner = max(1, 20000 // max(scene.L, 1))
    factor = best_time(lambda: f(ldl._symbolic, ldl._numeric, pv, 1e-11), repeats, inner)
    solve = best_time(lambda: s(ldl._symbolic, ldl._numeric, pb, px), repeats, inner)
    info = ldl.info
    return {"name": name, "L": scene.L, "analyse": analyse_s, "nnz_L": info["nnz_L"], "algorithm": info["algorithm"],
            "blocks": info["blocks"], "factor": factor, "solve": solve, "residual": residual}


def step_time(repeats: int) -> float:
    import linknet_core as ln

    sim = ln.Simulator(builders.net(100, 100), method="rattle", dt=1e-4, error_estimate=False)
    sim.advance(1e-4)
    steps = 10
    best = float("inf")
    for _ in range(max(3, repeats // 3)):
        start = time.thread_time()
        sim.advance(sim.state.t + steps * 1e-4)
        best = min(best, (time.thread_time() - start) / steps)
    return best


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--step", action="store_true", help="also time RATTLE steps of the 100 x 100 net")
    parser.add_argument("--portable", action="store_true", help="the portable supernodal kernels, not AVX2")
    parser.add_argument("--library", help="a shared library to load instead of the package's (development)")
    args = parser.parse_args(argv)
    lib = ctypes.CDLL(args.library) if args.library else None
    if args.portable:
        vector_kernels(False, lib)

    net = builders.net(100, 100)
    first, second, _ = pair_values(net, net.X0)
    rows = [measure("net 100x100, AMD", net, None, args.repeats, lib),
            measure("net 100x100, previous (MMD/RCM)", net, previous_ordering(net.L, first, second, lib),
                    args.repeats, lib)]
    for name, scene in (("net_10x10", load_scene(MODELS / "net_10x10.json")),
                        ("chain_100", load_scene(MODELS / "chain_100.json")),
                        ("tree (binary, depth 9)", hanging_tree(9))):
        rows.append(measure(name, scene, analyse(scene).ordering, args.repeats, lib))

    print(f"{'scene, ordering':34s} {'L':>6s} {'analyse':>9s} {'nnz(L)':>8s} {'algorithm':>10s} {'blocks':>6s} "
          f"{'factor':>11s} {'solve':>11s} {'f + 6 s':>11s} {'residual':>9s}")
    for r in rows:
        print(f"{r['name']:34s} {r['L']:6d} {r['analyse'] * 1e3:7.2f}ms {r['nnz_L']:8d} {r['algorithm']:>10s} "
              f"{r['blocks']:6d} {r['factor'] * 1e6:9.1f}us {r['solve'] * 1e6:9.1f}us "
              f"{(r['factor'] + 6 * r['solve']) * 1e6:9.1f}us {r['residual']:9.1e}")
    print(f"(supernodal factorisation with AVX2 kernels: {'yes' if vector_kernels(None, lib) else 'no'})")
    if args.step:
        step = step_time(args.repeats)
        ldl = rows[0]["factor"] + 2 * rows[0]["solve"]
        print(f"\nRATTLE step, net 100x100 (dt 1e-4 s): {step * 1e3:.2f} ms; factor + 2 solves of A {ldl * 1e3:.2f} ms "
              f"({100 * ldl / step:.0f} %), the rest of the step {(step - ldl) * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
