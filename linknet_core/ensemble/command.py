"""``linknet ensemble``: a parameter study or Monte Carlo run from the command line, and the tools for its file.

    linknet ensemble models/chain_10.json --vary M[3]=0.5:2:10 --vary R[1..10]=0.09:0.11:5 --t-end 2 \\
        --out study.nc [--scheduler tcp://host:8786] [--plot study.png] [--fmu chain_10.fmu]
    linknet ensemble consolidate study.nc [-o self_contained.nc] [--remove-shards]
    linknet ensemble recover study.shards [-o study.nc]
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from typing import Callable

import numpy as np

from linknet_core.errors import LinknetError
from linknet_core.options import (_output, count, positive_number, random_seed, readable_file, readable_file_with,
                                  relative_tolerance, sample_count, text_with)


@dataclass(frozen=True)
class Distribution:
    """A --sample distribution: its two parameters' names, the rule they must meet (checked by ``problem``, which
    says what breaks it, or None), and its draws. numpy's own checks would end the command in a traceback."""

    parameters: tuple[str, str]
    rule: str
    problem: Callable[[float, float], str | None]
    draw: Callable[[np.random.Generator, float, float, int], np.ndarray]


_DISTRIBUTIONS = {
    "uniform": Distribution(
        ("LOW", "HIGH"), "LOW <= HIGH, and HIGH - LOW a finite number",
        lambda low, high: (f"LOW = {low:g} is above HIGH = {high:g}" if low > high else
                           f"HIGH - LOW = {high - low:g} overflows" if not math.isfinite(high - low) else None),
        lambda rng, low, high, n: rng.uniform(low, high, n)),
    "normal": Distribution(
        ("MEAN", "SD"), "SD >= 0 (a standard deviation)",
        lambda mean, sd: f"SD = {sd:g} is negative" if sd < 0 else None,
        lambda rng, mean, sd, n: rng.normal(mean, sd, n)),
}
_SAMPLE_FORMS = " or ".join(f"NAME={kind}:{':'.join(d.parameters)}" for kind, d in _DISTRIBUTIONS.items())


_NUMBER = r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
# the form of each text option is checked when it is parsed, its meaning (names against the scene) before the run
vary_text = text_with("NAME=VALUES", r"[^=\s]+=\S.*", "M[3]=0.5:2:10")
sample_text = text_with(_SAMPLE_FORMS, rf"[^=\s]+=({'|'.join(_DISTRIBUTIONS)}):{_NUMBER}:{_NUMBER}",
                        "M[3]=uniform:0.5:2")
output_list = text_with("a comma-separated list of X, U, T, Freact, or none", r"(?i:none)|\w+(\s*,\s*\w+)*", "X,T")
mass_text = text_with("a mass (1-based number or name)", r".+", "11")
scheduler_address = text_with("a Dask scheduler address", r"(\w+://)?\S+:\d+", "tcp://host:8786")


TOOLS = {
    "consolidate": "write a study file as one self-contained file: its trajectories copied in from the shard files "
                   "of the folder beside it (study.shards for study.nc), which it then no longer needs",
    "recover": "rebuild a study file from its shard folder (the study's process died, or the file was lost): every "
               "member a shard holds, the others marked missing",
}
_TOOLS_TEXT = ("The study file's tools: 'linknet ensemble consolidate STUDY.nc [-o OUT.nc] [--remove-shards]' "
               "(one self-contained file) and 'linknet ensemble recover STUDY.shards [-o STUDY.nc]' (rebuild the "
               "study file from its shards); each has --help.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    from linknet_core.integrators import METHODS

    p.epilog = _TOOLS_TEXT

    p.add_argument("scene", nargs="?", type=readable_file, help="scene JSON file (with --fmu, the scene the FMU was built from; an FMU "
                                            "built on pythonfmu carries its scene, and may stand here itself)")
    p.add_argument("--fmu", metavar="FMU", type=readable_file_with((".fmu",), "FMU"), help="run every member through this linknet FMU (build_fmu.py, pythonfmu "
                                                "or --native) with fmpy")
    p.add_argument("--vary", action="append", type=vary_text, default=[], metavar="NAME=VALUES",
                   help="a grid axis: M[3]=0.5:2:10 (start:stop:count, both ends included), R[1..10]=0.09,0.1 "
                        "(a list; a..b sets a range of indices to the same value), g[3]=-1.62, F[11,3]=0:5:6 "
                        "(constant input force), integrator=rattle,dop853, step=..., tolerance=...; scene "
                        "studies also X0[k,i], U0[k,i], drag[k], stiffness[s], damping[s], rest_length[s]. "
                        "Several --vary make a full factorial grid")
    p.add_argument("--sample", action="append", type=sample_text, default=[], metavar="NAME=DIST:A:B",
                   help="Monte Carlo: NAME drawn from uniform:LOW:HIGH (LOW <= HIGH) or normal:MEAN:SD (SD >= 0), "
                        "--n-samples times (with --vary, every grid point runs every sample)")
    p.add_argument("--samples", metavar="CSV", type=readable_file, help="parameter sets from a CSV file: a header of parameter "
                                                    "names, one member per row")
    p.add_argument("--n-samples", type=count, default=100, help="number of --sample draws (default 100)")
    p.add_argument("--seed", type=random_seed, default=0, help="random seed of --sample (default 0)")
    p.add_argument("--t-end", type=positive_number, required=True, help="end time of every member, s")
    p.add_argument("--method", choices=sorted(METHODS), help="integration method (default rattle, or dop853 with --rtol; an FMU keeps its "
                                    "own unless given)")
    step = p.add_mutually_exclusive_group()
    step.add_argument("--dt", type=positive_number, help="step of a fixed-step method, s (default 1e-3)")
    step.add_argument("--rtol", type=relative_tolerance, help="tolerance of an adaptive method")
    p.add_argument("--atol", type=positive_number, help="absolute tolerance of an adaptive method")
    p.add_argument("--n-out", type=sample_count, default=201, help="output samples per member (default 201)")
    p.add_argument("--outputs", type=output_list, default="X,U,T",
                   help="what to keep per member and time, of X,U,T,Freact (default X,U,T; 'none' keeps only the "
                        "quantities of interest)")
    p.add_argument("--tip", type=mass_text, help="mass whose final position is reported (1-based number or name; default the "
                                 "last free mass)")
    p.add_argument("--project-initial", action=argparse.BooleanOptionalAction, default=None,
                   help="project initial positions onto each member's link lengths (default: when R or X0 "
                        "is varied)")
    p.add_argument("--out", type=_output((".nc",), "the study (a netCDF file)"), help="netCDF file the members stream into (read it with xarray.open_dataset)")
    p.add_argument("--scheduler", metavar="ADDR", type=scheduler_address, help="run on an existing Dask cluster (tcp://host:8786) instead "
                                                       "of a local cluster")
    p.add_argument("--connect-timeout", metavar="SECONDS", type=positive_number, default=None,
                   help="seconds to reach the --scheduler and see its Dask handshake (default 10); an address where "
                        "no scheduler answers (refused, unreachable, the dashboard's HTTP port, a silent server) is "
                        "one line saying what was found there")
    p.add_argument("--workers", type=count, help="worker processes of the local cluster (default one per core)")
    p.add_argument("--members-per-task", type=count, help="fixed batch size (default: sized from the member time)")
    p.add_argument("--plot", metavar="PNG", type=_output((".png",), "the plot"), help="draw the quantities of interest against the varied parameters")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _vary(texts, scene) -> dict:
    from linknet_core.ensemble.parameters import parse_name, parse_values

    vary, given = {}, {}
    for text in texts:
        name, sep, values = text.partition("=")
        if not sep:
            raise LinknetError(f"--vary {text!r}: write NAME=VALUES, e.g. M[3]=0.5:2:10")
        parameter = parse_name(name, scene)
        if parameter.name in vary:  # the second would silently replace the first
            raise LinknetError(f"--vary {parameter.name} is given twice ({given[parameter.name]!r} and {text!r}): "
                               "vary each parameter once, all its values in one --vary (a list a,b,c or "
                               "start:stop:count)")
        vary[parameter.name] = parse_values(values, parameter)
        given[parameter.name] = text
    return vary


def parse_sample(text: str) -> tuple[str, Distribution, float, float]:
    """A --sample text: (the parameter's name, the distribution, its two parameters), each parameter a finite number
    and the two meeting the distribution's rule; a LinknetError naming the parameter, the distribution and the rule
    otherwise."""
    name, _, spec = text.partition("=")
    kind, *numbers = spec.split(":")
    if kind not in _DISTRIBUTIONS or len(numbers) != 2:
        raise LinknetError(f"--sample {text!r}: write {_SAMPLE_FORMS}")
    distribution = _DISTRIBUTIONS[kind]
    form = f"{kind}:{':'.join(distribution.parameters)}"
    values = []
    for parameter, number in zip(distribution.parameters, numbers):
        value = _finite_number(number)
        if value is None:
            raise LinknetError(f"--sample {text!r}: {parameter} = {number!r} of the {kind} distribution "
                               f"({form}) must be a finite number")
        values.append(value)
    problem = distribution.problem(*values)
    if problem:
        raise LinknetError(f"--sample {text!r}: {problem}; the {kind} distribution ({form}) needs {distribution.rule}")
    return name, distribution, values[0], values[1]


def _finite_number(text: str) -> float | None:
    """text as a finite number, or None (not a number, or inf or nan)."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def read_samples_csv(path, scene) -> dict:
    """The parameter sets of a --samples CSV file: a header of parameter names, then one member per line, a value per
    name. A line with another number of values, or a cell of a numeric parameter that is not a finite number, is
    refused naming the file, the line and the column."""
    from linknet_core.ensemble.parameters import check_values, parse_name

    try:
        with open(path) as f:
            header = [name.strip() for name in f.readline().strip().split(",")]
            rows = [(number, line.strip().split(",")) for number, line in enumerate(f, start=2) if line.strip()]
    except OSError as exc:
        raise LinknetError(f"cannot read --samples {path}: {exc.strerror}") from None
    if not rows:
        raise LinknetError(f"--samples {path}: no parameter sets below the header (one member per line)")
    for number, row in rows:
        if len(row) != len(header):
            raise LinknetError(f"--samples {path}: line {number} has {len(row)} value(s), the header names "
                               f"{len(header)} ({', '.join(header)})")
    columns: dict = {}
    for j, name in enumerate(header):
        parameter = parse_name(name, scene)
        if parameter.name in columns:  # the second column would silently replace the first
            raise LinknetError(f"--samples {path}: the header names {parameter.name} twice (column {j + 1}); give "
                               "each parameter one column")
        cells = [(number, row[j].strip()) for number, row in rows]
        if parameter.family.text:
            columns[parameter.name] = check_values(parameter, [cell for _, cell in cells])
            continue
        values = []
        for number, cell in cells:
            value = _finite_number(cell)
            if value is None:
                raise LinknetError(f"--samples {path}: line {number}, column {j + 1} ({name}): {cell!r} is not a "
                                   "finite number")
            values.append(value)
        columns[parameter.name] = check_values(parameter, values)
    return columns


def _samples(args, scene) -> dict | None:
    from linknet_core.ensemble.parameters import parse_name

    columns: dict = read_samples_csv(args.samples, scene) if args.samples else {}
    csv_names = set(columns)
    rng = np.random.default_rng(args.seed)
    for text in args.sample:
        name, distribution, a, b = parse_sample(text)
        parameter = parse_name(name, scene)
        if parameter.name in columns:  # the second would silently replace the first
            raise LinknetError(f"--sample {text!r}: {parameter.name} is already set by "
                               + ("--samples" if parameter.name in csv_names else "an earlier --sample")
                               + "; sample each parameter once")
        draws = distribution.draw(rng, a, b, args.n_samples)
        if columns and len(next(iter(columns.values()))) != draws.size:
            raise LinknetError(f"--sample draws {draws.size} values (--n-samples) but --samples has "
                               f"{len(next(iter(columns.values())))} rows")
        columns[parameter.name] = draws
    return columns or None


def tool_parser(argv) -> argparse.ArgumentParser | None:
    """The parser of a ``linknet ensemble consolidate|recover ...`` command line (None for any other): the
    study's parser takes a scene as its first word, so the tools are parsed apart (the CLI asks here first). Its
    namespace has ``command`` "ensemble" and ``tool`` the tool's name, which ``cmd_ensemble`` runs."""
    from linknet_core.options import one_line_errors

    if len(argv) < 2 or argv[0] != "ensemble" or argv[1] not in TOOLS:
        return None
    parser = argparse.ArgumentParser(prog="linknet")
    ensemble = parser.add_subparsers(dest="command", required=True).add_parser("ensemble", epilog=_TOOLS_TEXT)
    tools = ensemble.add_subparsers(dest="tool", required=True)
    consolidate = tools.add_parser("consolidate", help=TOOLS["consolidate"], description=TOOLS["consolidate"] + (
        ". It reads bit for bit as the study file did; written through a temporary file renamed when complete."))
    consolidate.add_argument("study", type=readable_file_with((".nc",), "study file"),
                             help="the study file (its shard folder beside it)")
    consolidate.add_argument("-o", "--out", type=_output((".nc",), "the self-contained study (a netCDF file)"),
                             help="where to write the self-contained file (default: replace STUDY itself)")
    consolidate.add_argument("--remove-shards", action="store_true",
                             help="remove the shard folder once STUDY itself is self-contained (not with -o)")
    recover = tools.add_parser("recover", help=TOOLS["recover"], description=TOOLS["recover"] + (
        ". The folder keeps the study's layout (layout.nc) and its shards; beside the folder the file reads its "
        "trajectories from them, elsewhere it is self-contained. A complete study is never replaced."))
    recover.add_argument("shards", metavar="SHARDS_DIR", help="the study's shard folder (study.shards)")
    recover.add_argument("-o", "--out", type=_output((".nc",), "the study (a netCDF file)"),
                         help="the study file to write (default: the folder's own, study.nc for study.shards)")
    one_line_errors(parser)
    return parser


def cmd_tool(args) -> int:
    """``linknet ensemble consolidate`` and ``linknet ensemble recover``."""
    from linknet_core.ensemble.study_files import consolidate, recover

    if args.tool == "consolidate":
        written = consolidate(args.study, args.out, remove_shards=args.remove_shards)
        print(f"wrote {written}: self-contained, its trajectories in the file"
              + (f"; removed the shard folder beside {args.study}" if args.remove_shards else ""))
        return 0
    recovery = recover(args.shards, args.out)
    print(recovery.text())
    return 0


def cmd_ensemble(args) -> int:
    if getattr(args, "tool", None):
        return cmd_tool(args)
    from linknet_core.ensemble import load_source, ensemble, plot, summary
    from linknet_core.ensemble.parameters import NOTHING_TO_VARY

    if args.plot and not args.plot.lower().endswith(".png"):
        raise LinknetError(f"--plot {args.plot}: the plot is a PNG file")
    scene = load_source(args.scene, args.fmu)[0]
    vary = _vary(args.vary, scene)
    samples = _samples(args, scene)
    if not vary and not samples:  # the library's rule and words (make_plan)
        raise LinknetError(NOTHING_TO_VARY)
    outputs = [] if args.outputs.strip().lower() == "none" else [o.strip() for o in args.outputs.split(",")
                                                                  if o.strip()]
    try:
        ds = ensemble(args.scene, fmu=args.fmu, vary=vary, samples=samples, t_end=args.t_end, method=args.method,
                      dt=args.dt, rtol=args.rtol, atol=args.atol, n_out=args.n_out, outputs=outputs, tip=args.tip,
                      project_initial=args.project_initial, out=args.out, client=args.scheduler,
                      connect_timeout=args.connect_timeout,
                      workers=args.workers, members_per_task=args.members_per_task, progress=not args.no_progress)
    except KeyboardInterrupt as exc:
        from linknet_core.ensemble.shards import folder_for

        # the library's note says where the finished members are; without one the file did not close
        notes = getattr(exc, "__notes__", None)
        kept = f"; {notes[0]}" if notes else (
            f"; should {args.out} not open, rebuild it from the shards beside it: linknet ensemble recover "
            f"{folder_for(args.out)}" if args.out else "")
        print(f"linknet ensemble: interrupted{kept}", file=sys.stderr)
        return 130
    except (LinknetError, SystemExit):
        raise
    except Exception as exc:  # Dask, HDF5, the network: one line, as every linknet error (the API raises them)
        raise LinknetError(f"{type(exc).__name__}: {exc}") from None
    print(summary(ds))
    if args.out:
        print(f"wrote {args.out}")
    if args.plot:  # whole or not at all; a failed write is one line naming it (WriteError, exit 1)
        from linknet_core.output import atomic_write

        atomic_write(args.plot, lambda tmp: plot(ds, tmp))
        print(f"wrote {args.plot}")
    return 0
