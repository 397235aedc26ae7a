"""Cold start: the first `linknet simulate` in a fresh process with every cache removed, against the second.

For each tree (a checkout of the package) and each command, in a fresh process each:

    python -m linknet_core.cli simulate models/pendulum.json --t-end 2 --method dop853 --rtol 1e-8 --no-progress
    python -m linknet_core.cli simulate models/chain_100.json --t-end 1 --method rattle --dt 1e-3 --no-progress

run once with every cache removed (first) and again right after (second, the caches the first one wrote now
warm). Every cache the package or its JIT keeps is removed: Python's bytecode (``__pycache__``) of the
package, numba's cache (its ``*.nbi``/``*.nbc`` index and data, next to the sources or in NUMBA_CACHE_DIR,
set to a fresh folder), and linknet's own code cache (LINKNET_CACHE_DIR, XDG_CACHE_HOME: fresh folders).
The installed dependencies (numpy, scipy, numba) keep their bytecode, as they have it after installation.

By default the tree's package and models are copied into a fresh folder for every (tree, command, repeat),
without any ``__pycache__`` (``--in-place`` instead deletes the caches inside the tree itself): a copy cannot
be warmed by someone else's process importing the same tree between the deletion and the first run, which on
a shared checkout happens. The copy keeps the built native library (it is part of the installed package).

Times: wall time of the process (what a user waits) and its CPU time (user + system, from
``getrusage(RUSAGE_CHILDREN)``: less sensitive to other jobs on a shared machine). Each (tree, command) is
repeated ``--repeats`` times, trees and commands interleaved; the table gives the median of the repeats and
the ratio first / second of the medians.

    python benchmarks/bench_cold_start.py --trees before=/work/before after=/work/main [--repeats 3] [--out DIR] [--merge]

Writes cold_start.json and cold_start.md into build/native_vs_numba (with --merge the tracked
docs/benchmarks/native_vs_numba, which ``python -m benchmarks.native_vs_numba report`` renders).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a file: the checkout's benchmarks package (this process measures nothing)
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.output import add_output_arguments, resolve, write_text  # noqa: E402

COMMANDS = {
    "pendulum dop853 rtol 1e-8, 2 s": ["models/pendulum.json", "--t-end", "2", "--method", "dop853", "--rtol", "1e-8"],
    "chain_100 rattle dt 1e-3, 1 s": ["models/chain_100.json", "--t-end", "1", "--method", "rattle", "--dt", "1e-3"],
}
CACHE_PATTERNS = ("__pycache__", "*.nbi", "*.nbc")
NO_BYTECODE = ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")


def _load():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def fresh_copy(tree: Path) -> Path:
    """The tree's package and models in a new folder, without any cache."""
    root = Path(tempfile.mkdtemp(prefix="linknet_cold_"))
    shutil.copytree(tree / "linknet_core", root / "linknet_core", ignore=shutil.ignore_patterns(*CACHE_PATTERNS))
    shutil.copytree(tree / "models", root / "models", ignore=shutil.ignore_patterns(*CACHE_PATTERNS))
    return root


def clear_in_place(tree: Path) -> None:
    for pattern in CACHE_PATTERNS:
        for path in sorted((tree / "linknet_core").rglob(pattern), reverse=True):
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)


def run(root: Path, args: list[str], env: dict) -> dict:
    """One fresh process of the CLI in ``root``: wall and CPU seconds, and its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", *args, "--no-progress"], cwd=root,
                          env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} in {root} failed:\n{proc.stdout}\n{proc.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "summary": proc.stdout.strip().splitlines()[-5:]}


def measure(trees: dict, repeats: int, in_place: bool, log=print) -> dict:
    results = {tree: {cmd: [] for cmd in COMMANDS} for tree in trees}
    for r in range(repeats):
        for cmd, args in COMMANDS.items():
            for tree, path in trees.items():
                caches = Path(tempfile.mkdtemp(prefix="linknet_cold_caches_"))
                # a user's Python writes bytecode where the package is: the second run must find it
                env = {k: v for k, v in os.environ.items() if k not in NO_BYTECODE}
                env.update(NUMBA_CACHE_DIR=str(caches / "numba"), LINKNET_CACHE_DIR=str(caches / "linknet"),
                           XDG_CACHE_HOME=str(caches / "xdg"), MPLCONFIGDIR=str(caches / "mpl"))
                if in_place:
                    root = path
                    clear_in_place(path)
                else:
                    root = fresh_copy(path)
                env["PYTHONPATH"] = str(root)
                first = run(root, args, env)
                second = run(root, args, env)
                where = subprocess.run([sys.executable, "-c", "import linknet_core; print(linknet_core.__file__)"],
                                       cwd=root, env=env, capture_output=True, text=True).stdout.strip()
                if Path(where).resolve().parent.parent != root.resolve():
                    raise RuntimeError(f"{tree}: the CLI imported {where}, not the package in {root}")
                numba_files = len(list((caches / "numba").rglob("*.nbi"))) + len(list(root.rglob("*.nbi")))
                results[tree][cmd].append({"first": first, "second": second, "numba_index_files": numba_files,
                                           "load": _load()})
                log(f"[{r + 1}/{repeats}] {tree:>8} {cmd}: first {first['wall_s']:.2f} s wall "
                    f"({first['cpu_s']:.2f} s CPU), second {second['wall_s']:.2f} s wall ({second['cpu_s']:.2f} s "
                    f"CPU): {first['wall_s'] / second['wall_s']:.2f}x; load {_load()}")
                if not in_place:
                    shutil.rmtree(root, ignore_errors=True)
                shutil.rmtree(caches, ignore_errors=True)
    return results


def summarise(results: dict) -> dict:
    out = {}
    for tree, per_cmd in results.items():
        for cmd, runs in per_cmd.items():
            row = {}
            for which in ("first", "second"):
                for unit in ("wall_s", "cpu_s"):
                    values = [x[which][unit] for x in runs]
                    row[f"{which}_{unit}"] = statistics.median(values)
                    row[f"{which}_{unit}_min"] = min(values)
                    row[f"{which}_{unit}_max"] = max(values)
            row["ratio_wall"] = row["first_wall_s"] / row["second_wall_s"]
            row["ratio_cpu"] = row["first_cpu_s"] / row["second_cpu_s"]
            out.setdefault(tree, {})[cmd] = row
    return out


def markdown(summary: dict, meta: dict) -> str:
    lines = ["# Cold start", "", f"`{meta['command']}`, {meta['date']}, {meta['machine']}; load average "
             f"{meta['load_start']} at the start, {meta['load_end']} at the end; {meta['repeats']} repeats per "
             f"tree and command (interleaved), median (min-max). Caches: {meta['mode']}.", "",
             "| tree | command | first run, s wall | second run, s wall | first / second (wall) | first, s CPU "
             "| second, s CPU | first / second (CPU) |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for tree, per_cmd in summary.items():
        for cmd, r in per_cmd.items():
            def cell(key):
                return f"{r[key]:.2f} ({r[key + '_min']:.2f}-{r[key + '_max']:.2f})"
            lines.append(f"| {tree} | {cmd} | {cell('first_wall_s')} | {cell('second_wall_s')} | "
                         f"**{r['ratio_wall']:.2f}** | {cell('first_cpu_s')} | {cell('second_cpu_s')} | "
                         f"{r['ratio_cpu']:.2f} |")
    lines.append("")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trees", nargs="+", required=True, metavar="NAME=PATH")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--in-place", action="store_true", help="delete the caches inside each tree instead of copying")
    add_output_arguments(ap, "native_vs_numba", tracked="native_vs_numba")
    args = ap.parse_args(argv)
    out = resolve(ap, args, "native_vs_numba", tracked="native_vs_numba")
    trees = {k: Path(v).resolve() for k, v in (item.split("=", 1) for item in args.trees)}
    meta = {"command": "python benchmarks/bench_cold_start.py --trees " + " ".join(args.trees)
            + f" --repeats {args.repeats}" + (" --in-place" if args.in_place else ""),
            "date": time.strftime("%Y-%m-%d %H:%M %Z"),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
                       f"{platform.python_version()}", "load_start": _load(), "repeats": args.repeats,
            "mode": ("deleted inside each tree (__pycache__, *.nbi, *.nbc under linknet_core/), fresh NUMBA_CACHE_DIR, "
                     "LINKNET_CACHE_DIR and XDG_CACHE_HOME" if args.in_place else
                     "package and models copied into a fresh folder without __pycache__ for every run pair, fresh "
                     "NUMBA_CACHE_DIR, LINKNET_CACHE_DIR and XDG_CACHE_HOME"),
            "trees": {k: str(v) for k, v in trees.items()}}
    results = measure(trees, args.repeats, args.in_place)
    meta["load_end"] = _load()
    summary = summarise(results)
    write_text(out / "cold_start.json", json.dumps({"meta": meta, "summary": summary, "runs": results}, indent=1))
    text = markdown(summary, meta)
    write_text(out / "cold_start.md", text)
    print(text)


if __name__ == "__main__":
    main()
