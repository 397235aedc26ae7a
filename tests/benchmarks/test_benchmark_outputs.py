"""Benchmarks write under build/ unless asked to merge (--merge) into the tracked docs/benchmarks.

The benchmarks run from a copy of benchmarks/ in a scratch checkout (linknet_core, models and fmu_src linked to the
real ones), so that whatever they write, by design or by mistake, lands in the scratch folder and never in the
real docs/. Their cheapest entry points that write results files are run for real (physics-free: the stress
suite's --combine, the before/after report, the kernel benchmark with no part selected); the others are run with an
--out inside docs/, which each must refuse before doing any work.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def checkout(tmp_path):
    shutil.copytree(ROOT / "benchmarks", tmp_path / "benchmarks", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("linknet_core", "models", "fmu_src", "build_fmu.py"):
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def run_mains(checkout: Path, calls: list[tuple[str, list[str]]]) -> list[dict]:
    """Each benchmarks.<module>.main(argv) in one process in the scratch checkout: its exit code (None when it
    returned) and the last line it wrote to stderr."""
    code = textwrap.dedent(f"""
        import contextlib, importlib, io, json
        report = []
        for module, argv in {calls!r}:
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                try:
                    importlib.import_module("benchmarks." + module).main(argv)
                    status = None
                except SystemExit as exc:
                    status = exc.code
            lines = err.getvalue().strip().splitlines()
            report.append({{"module": module, "status": status, "stderr": lines[-1] if lines else ""}})
        print(json.dumps(report))
    """)
    env = dict(os.environ, PYTHONPATH=str(checkout), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, "-c", code], cwd=checkout, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_results_go_to_build_without_merge(checkout):
    run_mains(checkout, [("stress", ["--combine"]), ("native_vs_numba", ["report"]),
                         ("bench_kernel", ["--no-kernel", "--quick"])])
    assert not (checkout / "docs").exists()
    assert files_under(checkout / "build") == ["kernel/quick/kernel.json", "kernel/quick/kernel.md",
                                               "native_vs_numba.md", "stress/stress.json", "stress/stress.md"]
    # written whole: every JSON parses (and no temporary is left beside it)
    assert json.loads((checkout / "build/stress/stress.json").read_text())["cases"] == []
    assert json.loads((checkout / "build/kernel/quick/kernel.json").read_text())["meta"]["quick"] is True


def test_merge_writes_the_tracked_folder_and_reads_what_is_there(checkout):
    tracked = checkout / "docs" / "benchmarks"
    tracked.mkdir(parents=True)
    # a case rerun on its own, as `stress --case whip --merge` leaves it: --combine --merge must gather it
    whip = {"case": "whip", "criterion": "c", "measured": {"peak": 1.0}, "passed": True, "seconds": 1.0}
    (tracked / "stress_whip.json").write_text(json.dumps({"command": "python -m benchmarks.stress --case whip",
                                                          "date": "2026-01-01T00:00:00+00:00", "cases": [whip]}))
    run_mains(checkout, [("stress", ["--combine", "--merge"]), ("native_vs_numba", ["report", "--merge"]),
                         ("bench_kernel", ["--no-kernel", "--merge"])])
    assert not (checkout / "build").exists()
    assert files_under(tracked) == ["kernel.json", "kernel.md", "native_vs_numba.md", "stress.json", "stress.md",
                                    "stress_whip.json"]
    combined = json.loads((tracked / "stress.json").read_text())
    assert [c["case"] for c in combined["cases"]] == ["whip"]
    assert combined["cases"][0]["command"] == "python -m benchmarks.stress --case whip"


# every benchmark that writes files, given an --out inside docs/ and (where it has one) no --merge; the arguments
# would otherwise start a real run, so a refusal that came late would show as a timeout or as files under docs/
REFUSED = [
    ("work_precision", ["--quick", "--out", "docs/benchmarks"]),
    ("work_precision", ["--render", "docs/benchmarks/results.json"]),
    ("bench_kernel", ["--quick", "--out", "docs/benchmarks/quick"]),
    ("stress", ["--quick", "--case", "whip", "--out", "docs/benchmarks"]),
    ("stress", ["--combine", "--out", "docs/benchmarks"]),
    ("moordyn_study", ["--out", "docs/benchmarks"]),
    ("degenerate_limit", ["--out", "docs"]),
    ("native_vs_numba", ["report", "--out", "docs/benchmarks/native_vs_numba"]),
    ("bench_cold_start", ["--trees", "a=.", "--out", "docs/benchmarks/native_vs_numba"]),
    ("bench_fixed_costs", ["--trees", "a=.", "--out", "docs/benchmarks/native_vs_numba"]),
    ("accuracy", ["--quick", "--out", "docs/accuracy_table.md"]),
    ("bench_fmu", ["--quick", "--out", "docs/bench_fmu.json"]),
    ("bench_fmu_native", ["--quick", "--out", "docs/bench_fmu_native.json"]),
    ("bench_ensemble", ["--quick", "--out", "docs/bench_ensemble.json"]),
    ("bench_fmu_directional", ["--out", "docs/bench_directional"]),
    ("bit_identity", ["--trees", "a=.", "--out", "docs/bit_identity"]),
]


def test_an_out_inside_docs_is_refused_without_merge(checkout):
    (checkout / "docs").mkdir()
    report = run_mains(checkout, REFUSED)
    for (module, argv), r in zip(REFUSED, report):
        assert r["status"] == 2, (module, argv, r)  # argparse's usage error, before any work
        option = "--render" if "--render" in argv else "--out"
        assert f"error: {option} docs" in r["stderr"], r
        assert "--merge" in r["stderr"], r
    assert files_under(checkout / "docs") == []
    assert not (checkout / "build").exists()
