"""Before/after comparison of two trees of linknet on one machine: kernel benchmark and work-precision.

Each tree runs its own scripts (``python -m benchmarks.bench_kernel``, ``python -m benchmarks.work_precision``)
in a fresh process with the tree as working directory and first on PYTHONPATH, so each measures its own
package. The trees are interleaved run by run (a change of the machine's load hits both alike) and every
figure is the best of the rounds. A JIT-compiled tree gets one numba cache folder for all its runs
(NUMBA_CACHE_DIR), outside the tree, so its runs after the first load compiled code as a user's would.

    python -m benchmarks.native_vs_numba kernel --trees before=/work/before after=/work/main [--rounds 2]
    python -m benchmarks.native_vs_numba work-precision --trees before=/work/before after=/work/main \
        [--rounds 2] [--scenes pendulum chain_10 chain_100 net_10x10] [--wp-args='--sweep-budget 45']
    python -m benchmarks.native_vs_numba report [--merge]

``work-precision`` runs linknet's own methods only (the peers are the same code in both trees), every tree with
the same work_precision arguments (--wp-args, for example smaller sweep budgets for both), and records each
sweep's wall time and the load when it started. ``kernel`` and ``work-precision`` write DIR/kernel.json and
DIR/work_precision.json (DIR: build/native_vs_numba; --out DIR; with --merge the tracked
docs/benchmarks/native_vs_numba), each tree's raw rounds included; ``kernel`` also writes the after tree's best
rounds in bench_kernel's own format (DIR/kernel_after/kernel.md). ``report`` renders DIR.md (build/native_vs_numba.md,
with --merge docs/benchmarks/native_vs_numba.md) from DIR/findings.md (written by hand), these JSON files and
bench_fixed_costs.py's and bench_cold_start.py's outputs in the same folder (they write there by the same rule).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.output import add_output_arguments, resolve, write_text

ROOT = Path(__file__).resolve().parent.parent
WP_SCENES = ("pendulum", "chain_10", "chain_100", "net_10x10")
LINKNET_METHODS = ("rattle", "yoshida4", "suzuki4", "yoshida6", "yoshida8", "dopri5", "dop853")
LEVELS = ("0.001", "1e-06", "1e-09")


def _load():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _meta(command: str) -> dict:
    return {"command": command, "date": time.strftime("%Y-%m-%d %H:%M %Z"), "load_start": _load(),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
                       f"{platform.python_version()}"}


def _env(tree: Path, numba_cache: Path) -> dict:
    return dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(numba_cache))


def _commit(tree: Path) -> str:
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "linknet_core"], cwd=tree, capture_output=True,
                           text=True)
    return head.stdout.strip() + (" + uncommitted changes in linknet_core/" if dirty.stdout.strip() else "")


def _check_tree(tree: Path, env: dict) -> None:
    where = subprocess.run([sys.executable, "-c", "import linknet_core; print(linknet_core.__file__)"], cwd=tree,
                           env=env, capture_output=True, text=True).stdout.strip()
    if Path(where).resolve().parent.parent != tree:
        raise RuntimeError(f"in {tree} the package imported is {where}")


# ------------------------------------------------------------------------------------------------ kernel
def _best_rows(rows_per_round: list[list[dict]], key: str, time_fields) -> list[dict]:
    """Row by row (matched on ``key``), each time field the best of the rounds; the rest from the first."""
    best = [dict(r) for r in rows_per_round[0]]
    for rows in rows_per_round[1:]:
        for b, r in zip(best, rows):
            assert b[key] == r[key]
            for f in time_fields:
                if f in r:
                    b[f] = min(b[f], r[f])
    return best


def _combine_kernel(rounds: list[dict]) -> dict:
    """Best of the rounds of bench_kernel's JSON, figure by figure (ratios recomputed from the bests)."""
    out = json.loads(json.dumps(rounds[0]))
    kernels = [r["kernel"] for r in rounds if "kernel" in r]
    if kernels:
        fields = [f for f in kernels[0]["rows"][0] if f.endswith("_ns") and "per_link" not in f]
        rows = _best_rows([k["rows"] for k in kernels], "links", fields)
        for row in rows:
            row["ratio"] = row["linknet_ns"] / row["c_ns"]
            row["ratio_fused"] = row["linknet_ns"] / row["c_fused_ns"]
            if "c_fused_core_flags_ns" in row:
                row["ratio_fused_core_flags"] = row["linknet_ns"] / row["c_fused_core_flags_ns"]
            row["ratio_general"] = row["linknet_general_ns"] / row["c_ns"]
            row["linknet_ns_per_link"] = row["linknet_ns"] / row["links"]
            row["c_ns_per_link"] = row["c_ns"] / row["links"]
        out["kernel"]["rows"] = rows
    planars = [r["planar_kernel"] for r in rounds if "planar_kernel" in r]
    if planars:
        rows = _best_rows([p["rows"] for p in planars], "links", ("ns_3d", "ns_2d"))
        for row in rows:
            row["ratio_2d_3d"] = row["ns_2d"] / row["ns_3d"]
        out["planar_kernel"]["rows"] = rows
    for part, keys in (("planar_integrators", ("3d", "2d")), ("integrators", ("numpy", "compiled", "native"))):
        parts = [r[part] for r in rounds if part in r]
        if not parts:
            continue
        rows = [json.loads(json.dumps(row)) for row in parts[0]["rows"]]
        for other in parts[1:]:
            for row, o in zip(rows, other["rows"]):
                assert (row["scene"], row["method"], row["rtol"]) == (o["scene"], o["method"], o["rtol"])
                for k in keys:
                    if k in row and o[k]["seconds"] < row[k]["seconds"]:
                        row[k] = o[k]
        for row in rows:
            if part == "planar_integrators":
                row["ratio_2d_3d"] = row["2d"]["seconds"] / row["3d"]["seconds"]
            else:
                fast = row.get("native", row.get("compiled"))
                row["speedup"] = row["numpy"]["seconds"] / fast["seconds"]
        out[part] = dict(parts[0], rows=rows)
    return out


def run_kernel(trees: dict, rounds: int, out: Path) -> dict:
    numba_cache = Path(tempfile.mkdtemp(prefix="linknet_numba_cache_"))
    raw = {t: [] for t in trees}
    meta = _meta("python -m benchmarks.native_vs_numba kernel --trees "
                 + " ".join(f"{k}={v}" for k, v in trees.items()) + f" --rounds {rounds}")
    meta["commits"] = {t: _commit(p) for t, p in trees.items()}
    order = list(trees.items())
    for i in range(rounds):
        # part 1 in every round (the order of the trees alternates), then part 2 (whole runs) the same way
        for tree, path in (order if i % 2 == 0 else order[::-1]):
            raw[tree].append(_kernel_run(tree, path, numba_cache, []))
    for i in range(rounds):
        for tree, path in (order if i % 2 == 0 else order[::-1]):
            raw[tree].append(_kernel_run(tree, path, numba_cache, ["--integrators", "--no-kernel"]))
    meta["load_end"] = _load()
    best = {t: _combine_kernel(r) for t, r in raw.items()}
    write_text(out / "kernel.json", json.dumps({"meta": meta, "trees": {k: str(v) for k, v in trees.items()},
                                                "best": best, "rounds": raw}, indent=1))
    last = list(trees)[-1]
    sys.path.insert(0, str(ROOT))
    from benchmarks.bench_kernel import write_outputs  # the after tree's renderer (this tree's script)

    best[last]["meta"] = dict(best[last]["meta"], command=meta["command"] + f" (tree {last}, best of the rounds)",
                              load_start=meta["load_start"], load_end=meta["load_end"])
    write_outputs(out / f"kernel_{last}", best[last])
    return best


def _kernel_run(tree: str, path: Path, numba_cache: Path, args: list[str]) -> dict:
    env = _env(path, numba_cache)
    _check_tree(path, env)
    with tempfile.TemporaryDirectory() as tmp:
        print(f"bench_kernel {' '.join(args)}: {tree} ({path}), load {_load()}", flush=True)
        subprocess.run([sys.executable, "-m", "benchmarks.bench_kernel", *args, "--out", tmp], cwd=path, env=env,
                       check=True)
        return json.loads((Path(tmp) / "kernel.json").read_text())


# ------------------------------------------------------------------------------------------------ work-precision
def run_work_precision(trees: dict, rounds: int, scenes, out: Path, extra_args=()) -> dict:
    """extra_args: passed to every tree's work_precision (for example a smaller --sweep-budget for both)."""
    numba_cache = Path(tempfile.mkdtemp(prefix="linknet_numba_cache_"))
    work = Path(tempfile.mkdtemp(prefix="linknet_wp_"))
    extra_args = list(extra_args)
    meta = _meta("python -m benchmarks.native_vs_numba work-precision --trees "
                 + " ".join(f"{k}={v}" for k, v in trees.items()) + f" --rounds {rounds} --scenes {' '.join(scenes)}"
                 + (f" --wp-args='{' '.join(extra_args)}'" if extra_args else ""))
    meta["commits"] = {t: _commit(p) for t, p in trees.items()}
    methods = [f"linknet-{m}" for m in LINKNET_METHODS]
    meta["inner_command"] = ("python -m benchmarks.work_precision --scenes SCENE --methods " + " ".join(methods)
                             + "".join(f" {a}" for a in extra_args) + " --out DIR --merge")
    order = list(trees.items())
    meta["runs"] = []
    for i in range(rounds):
        for j, scene in enumerate(scenes):
            # which tree goes first alternates scene by scene and round by round
            for tree, path in (order if (i + j) % 2 == 0 else order[::-1]):
                env = _env(path, numba_cache)
                _check_tree(path, env)
                load = _load()
                print(f"work_precision round {i + 1} {scene}: {tree} ({path}), load {load}", flush=True)
                start = time.perf_counter()
                subprocess.run([sys.executable, "-m", "benchmarks.work_precision", "--scenes", scene, "--methods",
                                *methods, *extra_args, "--out", str(work / f"{tree}_{i}"), "--merge"], cwd=path,
                               env=env, check=True)
                meta["runs"].append({"round": i + 1, "scene": scene, "tree": tree, "load_start": load,
                                     "wall_seconds": round(time.perf_counter() - start, 1)})
    meta["load_end"] = _load()
    raw = {t: [json.loads((work / f"{t}_{i}" / "results.json").read_text()) for i in range(rounds)] for t in trees}
    best = {}
    for tree, results in raw.items():
        per_scene = {}
        for scene in scenes:
            levels = {}
            for level in LEVELS:
                per = {}
                for res in results:
                    for name, v in res["scenes"][scene]["summary"][level]["per_method"].items():
                        if name not in per or v["seconds"] < per[name]["seconds"]:
                            per[name] = v
                lk = min(per, key=lambda n: per[n]["seconds"]) if per else None
                levels[level] = {"per_method": per, "linknet_best": lk,
                                 "seconds": per[lk]["seconds"] if lk else None}
            # the same setting in both trees: best time per (method, knob)
            settings = {}
            for res in results:
                for name, m in res["scenes"][scene]["methods"].items():
                    for row in m["runs"]:
                        if row.get("status") == "ok":
                            key = f"{name} {row['knob']}={row['value']:g}"
                            if key not in settings or row["seconds"] < settings[key]["seconds"]:
                                settings[key] = {"seconds": row["seconds"], "steps": row["steps"],
                                                 "error": row["error"]}
            per_scene[scene] = {"levels": levels, "settings": settings}
        best[tree] = per_scene
    write_text(out / "work_precision.json", json.dumps({"meta": meta, "trees": {k: str(v) for k, v in trees.items()},
                                                        "best": best, "rounds": _slim(raw)}, indent=1))
    return best


def _slim(raw: dict) -> dict:
    """Each round's runs without what the comparison does not use (the per-run details stay in results.json)."""
    keep = ("status", "knob", "value", "seconds", "setup_seconds", "steps", "error", "message")
    return {tree: [{"meta": {k: r["meta"].get(k) for k in ("date", "load_average", "versions", "total_seconds")},
                    "scenes": {s: {m: [{k: row[k] for k in keep if k in row} for row in v["runs"]]
                                   for m, v in sres["methods"].items()} for s, sres in r["scenes"].items()}}
                   for r in results] for tree, results in raw.items()}


# ------------------------------------------------------------------------------------------------ report
def _fmt_s(s):
    if s is None:
        return "—"
    return f"{s * 1e3:.3g} ms" if s < 1 else f"{s:.3g} s"


def kernel_section(data: dict) -> list[str]:
    names = list(data["trees"])
    b, a = (data["best"][n] for n in names)
    m = data["meta"]
    lines = ["## Right-hand side of a chain (bench_kernel part 1)", "",
             f"`{m['command']}`; {m['date']}; load average {m['load_start']} at the start, {m['load_end']} at the "
             f"end. Commits: " + ", ".join(f"{t} {c}" for t, c in m["commits"].items()) + ". Each tree runs its "
             "own `python -m benchmarks.bench_kernel` (CPU time, best of 5 interleaved timings per round); every "
             "figure is the best of the rounds. The C references are the same files built the same way "
             f"(`{b['kernel']['flags']}`) in both trees' scripts; {names[1]} also builds the fused one with the "
             f"native core's flags (`{a['kernel'].get('core_flags', '')}`).", "",
             f"Fused C: the fastest `chain_rhs_fused.c` of both trees' runs (the same file and flags); "
             f"'{names[1]} / fused C, same runs': against the fused C timed in {names[1]}'s own runs, "
             "interleaved with it.", "",
             f"| links | fused C ns/eval | {names[0]} ns/eval | {names[0]} / fused C | {names[1]} ns/eval | "
             f"**{names[1]} / fused C** | {names[1]} / fused C, same runs | {names[1]} / fused C at the core's "
             f"flags | {names[1]} / {names[0]} | {names[0]} sparse LDL^T ns | {names[1]} sparse LDL^T ns | "
             "plain C ns |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for rb, ra in zip(b["kernel"]["rows"], a["kernel"]["rows"]):
        fused = min(rb["c_fused_ns"], ra["c_fused_ns"])  # the same kernel, built the same way: best of both
        lines.append(f"| {ra['links']} | {fused:.0f} | {rb['linknet_ns']:.0f} | {rb['linknet_ns'] / fused:.2f} | "
                     f"{ra['linknet_ns']:.0f} | **{ra['linknet_ns'] / fused:.2f}** | {ra['ratio_fused']:.2f} | "
                     f"{ra.get('ratio_fused_core_flags', float('nan')):.2f} | "
                     f"{ra['linknet_ns'] / rb['linknet_ns']:.2f} | {rb['linknet_general_ns']:.0f} | "
                     f"{ra['linknet_general_ns']:.0f} | {min(rb['c_ns'], ra['c_ns']):.0f} |")
    lines += ["", "Planar chain, right-hand side in 2-D vs 3-D (ns/eval):", "",
              f"| links | {names[0]} 3-D | {names[0]} 2-D | {names[1]} 3-D | {names[1]} 2-D | {names[1]} / "
              f"{names[0]} (2-D) |", "|---:|---:|---:|---:|---:|---:|"]
    for rb, ra in zip(b["planar_kernel"]["rows"], a["planar_kernel"]["rows"]):
        lines.append(f"| {ra['links']} | {rb['ns_3d']:.0f} | {rb['ns_2d']:.0f} | {ra['ns_3d']:.0f} | "
                     f"{ra['ns_2d']:.0f} | {ra['ns_2d'] / rb['ns_2d']:.2f} |")
    if "planar_integrators" in a and "planar_integrators" in b:
        lines += ["", "Whole runs, one `Simulator.advance(2.0)` after a warm-up call (bench_kernel part 2, CPU "
                  "time, best of the rounds, each the best of its interleaved runs), planar scenes in 2-D:", "",
                  f"| scene | method | setting | steps | {names[0]} ms | {names[1]} ms | {names[1]} / {names[0]} |",
                  "|---|---|---:|---:|---:|---:|---:|"]
        for rb, ra in zip(b["planar_integrators"]["rows"], a["planar_integrators"]["rows"]):
            setting = f"dt {ra['dt']:g}" if ra["dt"] else f"rtol {ra['rtol']:.0e}"
            lines.append(f"| {ra['scene']} | {ra['method']} | {setting} | {ra['2d']['steps']} | "
                         f"{1e3 * rb['2d']['seconds']:.3f} | {1e3 * ra['2d']['seconds']:.3f} | "
                         f"{ra['2d']['seconds'] / rb['2d']['seconds']:.2f} |")
    if "integrators" in a and "integrators" in b:
        lines += ["", "Adaptive Runge-Kutta, one `Simulator.advance(2.0)` (compiled/native best of 5; numpy one "
                  "run):", "",
                  f"| scene | method | rtol | steps {names[0]} / {names[1]} | {names[0]} compiled ms | {names[1]} "
                  f"native ms | {names[1]} / {names[0]} | {names[0]} numpy ms | {names[1]} numpy ms |",
                  "|---|---|---:|---|---:|---:|---:|---:|---:|"]
        for rb, ra in zip(b["integrators"]["rows"], a["integrators"]["rows"]):
            cb, ca = rb.get("compiled", rb.get("native")), ra.get("native", ra.get("compiled"))
            lines.append(f"| {ra['scene']} | {ra['method']} | {ra['rtol']:.0e} | {cb['steps']} / {ca['steps']} | "
                         f"{1e3 * cb['seconds']:.3f} | {1e3 * ca['seconds']:.3f} | {ca['seconds'] / cb['seconds']:.2f}"
                         f" | {1e3 * rb['numpy']['seconds']:.1f} | {1e3 * ra['numpy']['seconds']:.1f} |")
    return lines + [""]


def work_precision_section(data: dict) -> list[str]:
    names = list(data["trees"])
    m = data["meta"]
    b, a = (data["best"][n] for n in names)
    lines = ["## Work-precision: linknet's best time per scene and error level", "",
             f"`{m['command']}` (each round, each scene, each tree: `{m['inner_command']}` with the tree's own "
             f"script); {m['date']}; load average {m['load_start']} at the start, {m['load_end']} at the end. "
             "Commits: " + ", ".join(f"{t} {c}" for t, c in m["commits"].items()) + ". Wall time of the "
             "integration only (work_precision's own timing: runs under 0.2 s repeated up to 5 times, fastest "
             "kept), best of the rounds. Cell: fastest linknet method reaching the error level, and its time.", "",
             f"| scene | level | {names[0]} best | {names[1]} best | {names[1]} / {names[0]} | worst method "
             f"{names[1]} / {names[0]} at this level |", "|---|---:|---|---|---:|---|"]
    for scene in a:
        for level in LEVELS:
            lb, la = b[scene]["levels"][level], a[scene]["levels"][level]
            if not lb["linknet_best"] or not la["linknet_best"]:
                lines.append(f"| {scene} | {level} | — | — | | |")
                continue
            worst = None
            for name, v in la["per_method"].items():
                if name in lb["per_method"]:
                    r = v["seconds"] / lb["per_method"][name]["seconds"]
                    if worst is None or r > worst[1]:
                        worst = (name, r)
            lines.append(f"| {scene} | ≤ {level} m | {lb['linknet_best']} {_fmt_s(lb['seconds'])} | "
                         f"{la['linknet_best']} {_fmt_s(la['seconds'])} | **{la['seconds'] / lb['seconds']:.2f}** | "
                         f"{worst[0]} {worst[1]:.2f} |")
    if m.get("runs"):
        lines += ["", "Wall time of each tree's sweep per scene (all linknet methods; worker start-up, references, "
                  "warm-ups and repeats included) and the load average when it started:", "",
                  "| round | scene | " + " | ".join(f"{n} s | {n} load" for n in names) + " |",
                  "|---:|---|" + "---:|---|" * len(names)]
        cells = {}
        for run in m["runs"]:
            cells.setdefault((run["round"], run["scene"]), {})[run["tree"]] = run
        for (rnd, scene), per in cells.items():
            lines.append(f"| {rnd} | {scene} | " + " | ".join(
                f"{per[n]['wall_seconds']:.0f} | {per[n]['load_start'][0]:.1f}" if n in per else "— | —"
                for n in names) + " |")
        totals = {n: sum(r["wall_seconds"] for r in m["runs"] if r["tree"] == n) for n in names}
        lines.append("| | **total** | " + " | ".join(f"**{totals[n]:.0f}** | " for n in names) + " |")
    lines += ["", "Per setting (the same method at the same dt or rtol in both trees, so the same steps up to "
              "round-off): the distribution of the time ratio after / before over every setting both ran.", "",
              "| scene | settings | median | best | worst (setting) |", "|---|---:|---:|---:|---|"]
    for scene in a:
        sb, sa = b[scene]["settings"], a[scene]["settings"]
        ratios = sorted((sa[k]["seconds"] / sb[k]["seconds"], k) for k in sa if k in sb)
        if ratios:
            med = ratios[len(ratios) // 2][0]
            lines.append(f"| {scene} | {len(ratios)} | {med:.2f} | {ratios[0][0]:.2f} | {ratios[-1][0]:.2f} "
                         f"({ratios[-1][1]}: {_fmt_s(sb[ratios[-1][1]]['seconds'])} -> "
                         f"{_fmt_s(sa[ratios[-1][1]]['seconds'])}) |")
    return lines + [""]


def report(out: Path) -> None:
    """OUT.md (next to the folder): the hand-written findings (OUT/findings.md) and the generated tables."""
    lines = ["# Native core vs numba: before/after", ""]
    findings = out / "findings.md"
    if findings.exists():
        lines += [findings.read_text().rstrip(), ""]
    for name in ("kernel.json", "work_precision.json"):
        path = out / name
        if path.exists():
            data = json.loads(path.read_text())
            lines += (kernel_section if name == "kernel.json" else work_precision_section)(data)
    for name in ("fixed_costs.md", "cold_start.md"):
        path = out / name
        if path.exists():
            text = path.read_text().splitlines()
            lines += ["#" + text[0]] + [("#" + x if x.startswith("## ") else x) for x in text[1:]] + [""]
    target = out.parent / f"{out.name}.md"
    write_text(target, "\n".join(lines))
    print(f"wrote {target}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("kernel", "work-precision", "report"))
    ap.add_argument("--trees", nargs="+", metavar="NAME=PATH", help="before first, after second")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--scenes", nargs="+", default=list(WP_SCENES), help="work-precision scenes")
    ap.add_argument("--wp-args", default="", help="extra arguments for every tree's work_precision, the same for "
                    "all trees (for example '--sweep-budget 45 --sweep-cap 60')")
    add_output_arguments(ap, "native_vs_numba", tracked="native_vs_numba")
    args = ap.parse_args(argv)
    out = resolve(ap, args, "native_vs_numba", tracked="native_vs_numba")
    trees = {k: Path(v).resolve() for k, v in (x.split("=", 1) for x in args.trees or [])}
    if args.what == "kernel":
        run_kernel(trees, args.rounds, out)
    elif args.what == "work-precision":
        run_work_precision(trees, args.rounds, args.scenes, out, args.wp_args.split())
    report(out)


if __name__ == "__main__":
    main()
