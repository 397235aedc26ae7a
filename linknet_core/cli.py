"""The ``linknet`` command: simulate, analyze, check, ensemble, animate, view, fmu."""
from __future__ import annotations

import argparse
import warnings
import os
import sys
from pathlib import Path

import numpy as np

from linknet_core import visual  # light: matplotlib and plotly are imported only when a picture is drawn
from linknet_core.ensemble import command as ensemble_command  # light: Dask and xarray are imported only when a study runs
from linknet_core.errors import LinknetError
from linknet_core.output import WriteError
# one validated type per option, for every command (build_fmu.py imports them from here too)
from linknet_core.options import (  # noqa: F401
    _numbers_may_be_negative, _output, npz_path, one_line_errors, plot_path, positive_number, readable_file,
    relative_tolerance, sample_count, writable_path_problem)


def _add_simulate(sub):
    from linknet_core.integrators import METHODS

    p = sub.add_parser("simulate", help="simulate a scene and write t, X, U, T and diagnostics")
    p.add_argument("scene", type=readable_file, help="scene JSON file")
    p.add_argument("--t-end", type=positive_number, required=True, help="end time, s (> 0)")
    p.add_argument("--method", default=None, choices=sorted(METHODS),
                   help="dop853 (the default: error-controlled at rtol 1e-8), dopri5, or a fixed-step method: "
                        "rattle (the default with --dt), yoshida4, suzuki4, yoshida6, yoshida8 (dt 1e-3 unless --dt)")
    step = p.add_mutually_exclusive_group()
    step.add_argument("--dt", type=positive_number, help="step of a fixed-step method, s (> 0)")
    step.add_argument("--rtol", type=relative_tolerance,
                      help="tolerance of an adaptive method, in [1e-15, 0.1) (SI units; atol defaults to it)")
    p.add_argument("--atol", type=positive_number, help="absolute tolerance of an adaptive method (> 0)")
    p.add_argument("--n-out", type=sample_count, default=201, help="number of output samples, >= 2 (default 201)")
    p.add_argument("--out", type=npz_path, help="write arrays to this .npz (checked before the run)")
    p.add_argument("--plot", type=plot_path, help="write a PNG (or PDF, SVG) of positions and tensions against time")
    p.add_argument("--animate", metavar="PATH", type=visual.animation_path,
                   help="write an animation of the network (.gif, or .mp4 with ffmpeg); `linknet animate` has the "
                        "options")
    p.add_argument("--project-initial", action="store_true",
                   help="project initial positions onto the link lengths instead of refusing them")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (shown by default on a terminal, on stderr, for runs longer than a second)")
    p.add_argument("--no-error-estimate", action="store_true",
                   help="skip the companion run that estimates the run's error (about halves the run time; the "
                        "summary then says how accurate the run is not known)")
    p.add_argument("--rhs-kernel", choices=["numpy", "casadi"], default="numpy",
                   help="right-hand side of the Runge-Kutta methods: numpy, or a casadi-generated C kernel "
                        "specialised to the scene (compiled once, cached)")


def _add_analyze(sub):
    p = sub.add_parser("analyze", help="rigidity and structure of a scene (Maxwell-Calladine counts)")
    p.add_argument("scene", type=readable_file, help="scene JSON file")


def _add_check(sub):
    p = sub.add_parser("check", help="check the numeric tension system against its casadi derivation")
    from linknet_core.symbolic import check as checks

    checks.add_arguments(p)


def _add_animate(sub):
    visual.add_animate_arguments(sub.add_parser(
        "animate", help="animate a run (GIF, MP4) or draw one frame (PNG): links coloured by tension"))


def _add_view(sub):
    visual.add_view_arguments(sub.add_parser(
        "view", help="interactive 3-D view of a run in one self-contained HTML file (time slider, tension on hover)"))


def _add_ensemble(sub):
    ensemble_command.add_arguments(sub.add_parser(
        "ensemble", help="parameter study or Monte Carlo run on Dask, results as a netCDF dataset (docs/ensemble.md)"))


def cmd_simulate(args) -> int:
    from linknet_core.accuracy import DEFAULT_STEP, AccuracyWarning, default_method
    from linknet_core.integrators import METHODS
    from linknet_core.scene.description import load_scene
    from linknet_core.simulator.settings import RunSettings
    from linknet_core.simulator.simulator import SimulationInterrupted, simulate

    scene = load_scene(args.scene)
    method = default_method(args.method, args.dt)
    dt = args.dt
    if dt is None and not METHODS[method].adaptive:
        dt = DEFAULT_STEP
    settings = RunSettings(method=method, dt=dt, rtol=args.rtol, atol=args.atol,
                           project_initial=args.project_initial or None, rhs_kernel=args.rhs_kernel,
                           error_estimate=not args.no_error_estimate)
    interrupted = False
    try:
        with warnings.catch_warnings(record=True) as caught:  # said once, below the summary, in the CLI's words
            warnings.simplefilter("always", AccuracyWarning)
            res = simulate(scene, args.t_end, n_out=args.n_out, progress=False if args.no_progress else None,
                           settings=settings)
    except SimulationInterrupted as stop:  # Ctrl-C: keep what was computed
        res, interrupted = stop.result, True
    if res.stats.get("initial"):
        for line in res.stats["initial"]:
            print("note:", line)
    print(res.summary())
    for w in caught:
        if issubclass(w.category, AccuracyWarning):
            print(f"linknet simulate: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    written = _write_outputs(res, args)
    if interrupted:
        what = f"wrote the {res.t.size} samples computed so far ({', '.join(written)})" if written else \
            "nothing was asked to be written"
        print(f"linknet simulate: interrupted at t = {res.t[-1]:g} s of {args.t_end:g} s; {what}", file=sys.stderr)
        return 130
    return 0


def _write_outputs(res, args) -> list:
    """Write what the options ask for (every path was checked before the run, by its type), each whole or not at
    all (linknet_core.output.atomic_write). A write that fails anyway (a full disk) is one line naming the file;
    the others are still written, the arrays are kept in the temporary folder instead (the line names where),
    and the command then ends with exit status 1: nothing computed is lost, no failure reported as success."""
    from linknet_core.output import atomic_write, rescue_path

    written, failed = [], []
    for path, write in ((args.out, res.save_npz),
                        (args.plot, lambda p: atomic_write(p, lambda tmp: plot_result(res, tmp))),
                        (args.animate, lambda p: visual.animate_result(res, p))):
        if not path:
            continue
        try:
            write(path)
        except LinknetError as exc:
            message = str(exc)
            if path is args.out:
                rescue = rescue_path(path)
                try:
                    res.save_npz(rescue)
                    message += f"; the results are in {rescue} instead"
                except WriteError as again:
                    message += (f"; keeping them in the temporary folder failed too ({again.reason}): they are "
                                f"lost, rerun with --out on a disk with room")
            print(f"linknet {args.command}: error: {message}", file=sys.stderr)
            failed.append(path)
            continue
        if path is not args.animate:
            print(f"wrote {path}")
        written.append(path)
    if failed:
        raise SystemExit(1)
    return written


def plot_result(res, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = res.scene
    fig, axes = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    free = scene.free_indices
    show = free if free.size <= 6 else free[np.linspace(0, free.size - 1, 6).astype(int)]
    for k in show:
        axes[0].plot(res.t, res.X[:, k, 0], label=f"x {scene.mass_names[k]}")
        axes[0].plot(res.t, res.X[:, k, 2], "--", label=f"z {scene.mass_names[k]}")
    axes[0].set_ylabel("position, m")
    axes[0].legend(fontsize=7, ncol=3)
    links = np.arange(scene.L) if scene.L <= 6 else np.linspace(0, scene.L - 1, 6).astype(int)
    for l in links:
        axes[1].plot(res.t, res.T[:, l], label=scene.link_label(int(l)))
    axes[1].set_ylabel("tension T, N")
    axes[1].legend(fontsize=7, ncol=2)
    axes[2].semilogy(res.t, np.maximum(res.residual, 1e-17), label="max constraint residual (rel.)")
    axes[2].semilogy(res.t, np.maximum(np.abs(res.energy - res.energy[0]) / res.energy_scale, 1e-17),
                     label="|energy error| (rel.)")
    axes[2].set_xlabel("t, s")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"{scene.name}: {res.method}, {res.stats.get('steps')} steps")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def cmd_analyze(args) -> int:
    from linknet_core.simulator.analysis import analyze_scene
    from linknet_core.scene.description import load_scene

    report = analyze_scene(load_scene(args.scene))
    print(report.text())
    return 0


def cmd_check(args) -> int:
    from linknet_core.symbolic import check as checks

    return int(checks.main(args))


def _add_fmu(sub):
    p = sub.add_parser("fmu", add_help=False, help="build a scene's FMU: build_fmu.py's options (linknet fmu --help)",
                       description="build_fmu.py, from this installed package or the checkout")
    p.add_argument("build_fmu_args", nargs=argparse.REMAINDER)


def build_fmu_script() -> Path:
    """build_fmu.py: in an installed package at linknet_core/fmu_export/ (setup.py puts it and fmu_src/ there), in a
    checkout (an editable install) at the top, beside linknet_core/."""
    here = Path(__file__).resolve().parent
    for script in (here / "fmu_export" / "build_fmu.py", here.parent / "build_fmu.py"):
        if script.is_file():
            return script
    raise LinknetError(f"build_fmu.py is neither in {here / 'fmu_export'} nor beside {here}: reinstall linknet")


def cmd_fmu(args) -> int:
    """`linknet fmu SCENE -o OUT.fmu [--native] ...`: the same code as build_fmu.py, run in this process."""
    import importlib.util

    script = build_fmu_script()
    spec = importlib.util.spec_from_file_location("build_fmu", script)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("build_fmu", module)
    spec.loader.exec_module(module)
    program, sys.argv[0] = sys.argv[0], "linknet fmu"  # what its messages name
    try:
        return int(module.main(args.build_fmu_args) or 0)
    finally:
        sys.argv[0] = program


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="linknet", description="Networks of point masses joined by rigid links.")
    parser.add_argument("--version", action="version", version=f"linknet {__import__('linknet_core').__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_simulate(sub)
    _add_analyze(sub)
    _add_check(sub)
    _add_ensemble(sub)
    _add_animate(sub)
    _add_view(sub)
    _add_fmu(sub)
    _numbers_may_be_negative(parser)
    one_line_errors(parser)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["fmu"]:  # every argument is build_fmu.py's, --help among them (argparse would take that one)
        return cmd_fmu(argparse.Namespace(command="fmu", build_fmu_args=argv[1:]))
    parser = ensemble_command.tool_parser(argv) or build_parser()  # linknet ensemble consolidate|recover
    args = parser.parse_args(argv)
    handlers = {"simulate": cmd_simulate, "analyze": cmd_analyze, "check": cmd_check, "animate": visual.cmd_animate,
                "view": visual.cmd_view, "ensemble": ensemble_command.cmd_ensemble, "fmu": cmd_fmu}
    try:
        return handlers[args.command](args)
    except WriteError as exc:  # an output that could not be written (a full disk): not the input's fault
        print(f"linknet {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except LinknetError as exc:
        print(f"linknet {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # before the first sample: nothing to keep
        print(f"linknet {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a write failing despite the checks (disk full, a path removed meanwhile)
        print(f"linknet {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
