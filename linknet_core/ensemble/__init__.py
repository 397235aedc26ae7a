"""Ensembles: parameter studies and Monte Carlo runs of one scene (or one linknet FMU) on Dask.

    import linknet_core as ln
    study = ln.ensemble("models/chain_10.json", vary={"M[11]": [0.5, 1, 2], "R[1..10]": [0.09, 0.1, 0.11]},
                        t_end=2, out="study.nc")          # 9 members, a local cluster with one worker per core
    study.max_tension                                       # xarray: (member), coordinates M[11], R[1..10]

    study = open_study("study.nc")                          # read back later, its shard files checked
    consolidate("study.nc", "whole.nc")                     # one self-contained file (recover: rebuild from shards)

Docs: docs/ensemble.md. Only numpy is imported with this package; Dask, xarray, h5netcdf and fmpy are
imported when a study runs (FMU hosts load linknet_core without them).
"""
from __future__ import annotations

import math
import tempfile
import time
import uuid
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from linknet_core.accuracy import DEFAULT_STEP, default_method
from linknet_core.errors import LinknetError
from linknet_core.integrators import METHODS
from linknet_core.scene import Scene, load_scene
from linknet_core.ensemble.parameters import FAMILIES, Plan, changes_positions, make_plan, parse_name, parse_values

DEFAULT_OUTPUTS = ("X", "U", "T")


def ensemble(scene=None, vary=None, samples=None, *, t_end: float, fmu=None, method: str | None = None,
             dt: float | None = None, rtol: float | None = None, atol: float | None = None, n_out: int = 201,
             output_dt: float | None = None, outputs=DEFAULT_OUTPUTS, tip=None, project_initial: bool | None = None,
             out=None, client=None, workers: int | None = None, members_per_task: int | None = None, progress=None,
             connect_timeout: float | None = None):
    """Run a study: one member per parameter set, each a ``Simulator`` run (or an FMU run through fmpy).

    scene: a :class:`Scene` or a scene JSON file.
    fmu: a linknet FMU (build_fmu.py, pythonfmu or ``--native``) built from that scene: every member then runs
        through it with fmpy. An FMU built on pythonfmu carries its scene, so ``scene`` may be left out (or be
        the ``.fmu`` itself); a native FMU needs the scene. A scene the FMU was not built from is refused.
    vary: ``{name: values}``, a full factorial grid (first name slowest). Names are the FMU's: ``M[3]``,
        ``R[1..10]`` (a range set to one value), ``g[3]``, ``F[11,3]`` (constant input force), ``integrator``,
        ``step``, ``tolerance``; library members also take ``X0[k,i]``, ``U0[k,i]``, ``drag[k]``,
        ``stiffness[s]``, ``damping[s]``, ``rest_length[s]``.
    samples: parameter sets: ``{name: values}`` of equal lengths, a list of dicts, or a DataFrame. With
        ``vary`` too, every grid point runs every sample.
    t_end, n_out / output_dt: outputs at ``n_out`` equally spaced times from 0 to t_end (as ``ln.simulate``).
    method, dt, rtol, atol: the solver (defaults as ``linknet simulate``: rattle with dt 1e-3, or dop853 when
        rtol is given; an FMU study keeps the FMU's own unless given).
    outputs: which of X, U, T, Freact to keep per member and time (``[]``: quantities of interest only).
    tip: the mass (1-based number or name) whose final position is reported; default the last free mass.
    project_initial: project initial positions onto the link lengths; default: yes when R or X0 is varied
        (a member's lengths would otherwise contradict the scene's positions), else the scene's option.
    out: netCDF file to write (members stream into it as they finish; with trajectories, those are in shard
        files in the folder beside it, ``NAME.shards``, which the file joins: keep the two together, or make one
        self-contained file with ``consolidate``; read it back with ``open_study``, which checks the shards);
        None keeps the study in memory.
    client: None (a local cluster: ``workers`` processes, default one per core, and the scheduler's own), a
        scheduler address, or a ``distributed.Client``. members_per_task: fixed batch size (default: adaptive).
    connect_timeout: seconds (default 10) to reach a scheduler address and see its Dask handshake; an address
        where none answers (refused, unreachable, an HTTP server such as the dashboard's port, a server that
        never answers) raises LinknetError naming the address and what was found there.
    progress: True for a progress bar on stderr, or a callable taking an ``engine.Progress``.

    Returns an xarray Dataset: X, U (member, time, mass, axis), T (member, time, link), Freact, the
    quantities of interest max_tension, max_tension_link, min_tension, tip_final, and per member status,
    error, run_seconds, worker, retried; the varied parameters are coordinates along member.
    Bad names, indices or options raise LinknetError before anything runs; a member whose values make an
    invalid scene, or whose run fails, is recorded with its error and the others complete.
    """
    from linknet_core.ensemble.engine import Engine, run_study
    from linknet_core.ensemble.members import OUTPUTS, StudySpec
    from linknet_core.ensemble.report import ProgressBar
    from linknet_core.ensemble.store import StudyFile, remove_study

    base, fmu_bytes, fmu_config, source = load_source(scene, fmu)
    plan = make_plan(base, vary, samples)
    if out is not None and Path(out).suffix.lower() != ".nc":  # the rule of linknet ensemble --out
        raise LinknetError(f"out={str(out)!r}: the study is written as a netCDF file, whose name ends in .nc")
    if not (isinstance(t_end, (int, float)) and math.isfinite(t_end) and t_end > 0):
        raise LinknetError(f"t_end must be a positive finite time, got {t_end!r}")
    times = _output_times(t_end, n_out, output_dt)
    outputs = tuple(outputs)
    unknown = sorted(set(outputs) - set(OUTPUTS))
    if unknown:
        raise LinknetError(f"unknown output(s) {unknown}; choose from {list(OUTPUTS)}")
    method, dt, rtol = _solver(method, dt, rtol, atol, fmu_config)
    if project_initial is None and changes_positions(plan.parameters):
        project_initial = True
    if fmu_bytes is not None:
        plan.check_fmu(atol)
        if project_initial and not base.options.get("project_initial_positions"):
            raise LinknetError(
                "this study changes link lengths (R), so initial positions must be projected onto them, but the "
                "FMU's scene does not allow it: rebuild the FMU from a scene with \"options\": "
                "{\"project_initial_positions\": true}, or pass project_initial=False to let such members fail")
    tip_index = _tip(base, tip)
    spec = StudySpec(study_id=uuid.uuid4().hex, scene=base.to_dict(), parameters=plan.parameters, times=times,
                     method=method, dt=dt, rtol=rtol, atol=atol, project_initial=project_initial, outputs=outputs,
                     tip=tip_index, fmu=fmu_bytes)

    keep_in_memory = out is None
    path = Path(tempfile.gettempdir()) / f"linknet-ensemble-{spec.study_id}.nc" if keep_in_memory else Path(out)
    if not keep_in_memory and path.parent and not path.parent.exists():
        raise LinknetError(f"cannot write {path}: folder {path.parent} does not exist")
    bar = ProgressBar() if progress is True else None
    on_progress = bar if bar is not None else (progress if callable(progress) else None)
    facts = {"scene_name": base.name, "scene": spec.scene, "source": source,
             "runs_through": "FMU (fmpy)" if fmu_bytes is not None else "library (Simulator)",
             "solver": _solver_text(method, dt, rtol, atol, plan, fmu_config), "method": method, "dt": dt, "rtol": rtol,
             "atol": atol, "t_end": float(t_end), "project_initial": None if project_initial is None
             else int(project_initial), "tip_mass": tip_index + 1, "tip_name": base.mass_names[tip_index],
             "varied": [p.name for p in plan.parameters], "grid_shape": list(plan.grid_shape),
             "n_samples": plan.n_samples, "created": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    started = time.perf_counter()
    sink = None
    final = None
    try:
        # connect first: an unreachable cluster leaves no file behind
        with Engine(client, workers, **_connect_timeout(connect_timeout, client)) as engine:
            facts["engine"] = engine.description
            try:
                sink = StudyFile(path, spec, plan, base, attrs=facts)
            except OSError as exc:
                raise LinknetError(f"cannot write {path}: {exc}") from None
            spec = replace(spec, shards=sink.shard_folder)  # where the workers write the members' trajectories
            stopped = None
            try:
                final = run_study(engine, spec, plan, sink, on_progress, members_per_task)
            except BaseException as exc:
                stopped = exc
                raise
            finally:
                if bar is not None:
                    bar.close()
                if final is not None:
                    facts.update(wall_seconds=time.perf_counter() - started,
                                 members_per_second=final.total / final.elapsed,
                                 first_result_seconds=None if final.first_result_seconds is None
                                 else final.first_result_seconds + final.started - started, workers=final.workers,
                                 failed=final.failed, retried=final.retried, tasks=final.tasks,
                                 member_cpu_seconds=final.member_cpu_seconds,
                                 client_write_cpu_seconds=final.write_cpu_seconds,
                                 worker_write_cpu_seconds=final.worker_write_cpu_seconds, complete=1)
                else:  # interrupted: the members written so far stay readable, marked as such
                    facts["complete"] = 0
                try:
                    sink.close(facts)
                finally:
                    if final is None and keep_in_memory:
                        remove_study(path)
                if stopped is not None and not keep_in_memory:
                    _note_where_members_are(stopped, path, sink)
    finally:
        # the study's workers are stopped now (a local cluster's) or have left it: a write one of them began
        # while the study ended is removed with what else the file does not map
        if sink is not None and final is None and not keep_in_memory:
            sink.tidy()
    return _open(path, keep_in_memory)


def _note_where_members_are(exc: BaseException, path: Path, sink) -> None:
    """Say on the exception that stopped a study (a Ctrl-C, a failure) where its finished members are and how to
    read them (Python shows a note under the exception's message; ``linknet ensemble`` prints it)."""
    from linknet_core.ensemble.shards import folder_for

    folder = folder_for(path)
    text = f"the {sink.members_kept} member(s) finished before the study stopped are in {path} (complete = 0)"
    if sink.shard_folder is not None:
        text += (f", their trajectories in the shard files of {folder} beside it: keep the two together, or make "
                 f"one self-contained file with: linknet ensemble consolidate {path}")
    if hasattr(exc, "add_note"):
        exc.add_note(text)
    else:  # Python 3.10: the note is kept where 3.11 keeps it (linknet ensemble reads it; tracebacks do not show it)
        exc.__notes__ = [*getattr(exc, "__notes__", []), text]


def _connect_timeout(seconds, client) -> dict:
    """Engine's keyword for ``connect_timeout=`` (None: its default, CONNECT_TIMEOUT), which bounds only the
    connection to a scheduler address."""
    if seconds is None:
        return {}
    if not isinstance(client, str):
        raise LinknetError("connect_timeout (--connect-timeout) bounds the connection to a scheduler address "
                           "(client='tcp://HOST:PORT', --scheduler); "
                           + ("the local cluster is started here" if client is None else "this client is connected"))
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not (math.isfinite(seconds)
                                                                                  and seconds > 0):
        raise LinknetError(f"connect_timeout must be a positive finite number of seconds, got {seconds!r}")
    return {"connect_timeout": float(seconds)}


def _open(path: Path, keep_in_memory: bool):
    from linknet_core.accuracy import warn_accuracy
    from linknet_core.ensemble.report import accuracy_note
    from linknet_core.ensemble.store import remove_study
    from linknet_core.ensemble.study_files import open_study

    ds = open_study(path)
    if keep_in_memory:
        ds.load()
        ds.close()
        remove_study(path)
    note = accuracy_note(ds)
    if note:
        warn_accuracy(f"{ds.attrs.get('scene_name')}: {note}")
    return ds


def load_source(scene, fmu=None):
    """(scene, FMU bytes or None, the FMU's own integrator/step/tolerance, description of the source).
    A ``.fmu`` given as the scene is the FMU, with the scene it carries."""
    from linknet_core.ensemble.members import read_fmu

    if fmu is None and not isinstance(scene, Scene) and scene is not None and str(scene).endswith(".fmu"):
        scene, fmu = None, scene
    if fmu is None:
        if scene is None:
            raise LinknetError("give a scene (a Scene or a scene JSON file), or an FMU")
        return (scene, None, {}, f"scene {scene.name}") if isinstance(scene, Scene) else \
            (load_scene(scene), None, {}, str(scene))
    try:
        data = Path(fmu).read_bytes()
    except OSError as exc:
        raise LinknetError(f"cannot read FMU {fmu}: {exc.strerror}") from None
    facts = read_fmu(data, str(fmu))
    if scene is None:
        if facts.scene is None:
            raise LinknetError(f"{fmu} carries no scene (a native FMU): give the scene it was built from too, "
                               f"e.g. ln.ensemble('models/NAME.json', fmu='{fmu}') or linknet ensemble "
                               f"models/NAME.json --fmu {fmu}")
        base = Scene.from_dict(facts.scene, source=str(fmu))
    else:
        base = scene if isinstance(scene, Scene) else load_scene(scene)
    facts.check_matches(base, str(fmu))
    return base, data, facts.defaults(), str(fmu)


def _output_times(t_end: float, n_out: int, output_dt: float | None) -> np.ndarray:
    """The same times as ``ln.simulate`` (so a member equals a serial run of it)."""
    if output_dt is not None:
        if not (output_dt > 0 and math.isfinite(output_dt)):
            raise LinknetError(f"output_dt must be a positive time, got {output_dt!r}")
        return np.linspace(0.0, t_end, max(1, int(round(t_end / output_dt))) + 1)
    if int(n_out) < 2:
        raise LinknetError(f"n_out must be at least 2 (t = 0 and t_end), got {n_out!r}")
    return np.linspace(0.0, t_end, int(n_out))


def _solver(method, dt, rtol, atol, fmu_config):
    """The study's method, dt and rtol. Library: as ``linknet simulate`` (the error-controlled default of
    linknet_core.accuracy; RATTLE when a step dt is given; a fixed-step method named without dt steps
    DEFAULT_STEP). FMU: None leaves the FMU's own setting."""
    for name, value in (("dt", dt), ("rtol", rtol), ("atol", atol)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise LinknetError(f"{name} must be a positive number, got {value!r}")
    if method is not None and method not in METHODS:
        raise LinknetError(f"unknown method {method!r}; choose one of {sorted(METHODS)}")
    if fmu_config:
        return method, dt, rtol
    method = default_method(method, dt)
    if METHODS[method].adaptive and dt is not None:
        raise LinknetError(f"method {method} chooses its own steps: give rtol, not dt")
    if not METHODS[method].adaptive and (rtol is not None or atol is not None) and dt is None:
        raise LinknetError(f"method {method} has a fixed step: give dt, not rtol/atol")
    if not METHODS[method].adaptive and dt is None:
        dt = DEFAULT_STEP
    return method, dt, rtol


def _solver_text(method, dt, rtol, atol, plan: Plan, fmu_config: dict) -> str:
    """'rattle dt=0.001', with the FMU's own settings where the study leaves them."""
    if fmu_config and method is None:
        method = f"{fmu_config['integrator']} (the FMU's)"
        adaptive = METHODS[fmu_config["integrator"]].adaptive
        dt = dt or (None if adaptive else fmu_config["step"])
        rtol = rtol or (fmu_config["tolerance"] if adaptive else None)
    text = method + (f" dt={dt:g}" if dt else "") + (f" rtol={rtol:g}" if rtol else "")
    text += f" atol={atol:g}" if atol else ""
    varied = {p.name for p in plan.parameters} & {"integrator", "step", "tolerance"}
    return text + (f" (varied: {', '.join(sorted(varied))})" if varied else "")


def _tip(scene: Scene, tip) -> int:
    """0-based index of the tip mass: a 1-based number or a name; default the last free mass."""
    if tip is None:
        return int(scene.free_indices[-1])
    if isinstance(tip, (int, np.integer)) and not isinstance(tip, bool):
        if not 1 <= tip <= scene.K:
            raise LinknetError(f"tip mass {tip} is outside 1..{scene.K}")
        return int(tip) - 1
    if str(tip) in scene.mass_names:
        return scene.mass_names.index(str(tip))
    if str(tip).isdigit():
        return _tip(scene, int(tip))
    raise LinknetError(f"no mass {tip!r} in {scene.name} (give a 1-based number or a name)")


from linknet_core.ensemble.report import plot, summary  # noqa: E402  (matplotlib is imported only when plotting)

# a study file read back, made self-contained, rebuilt from its shards (study_files.py); imported when first used,
# as they import h5py and xarray
_STUDY_FILE_TOOLS = ("open_study", "consolidate", "recover", "MissingShardsError")


def __getattr__(name):
    if name in _STUDY_FILE_TOOLS:
        from linknet_core.ensemble import study_files

        return getattr(study_files, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["ensemble", "summary", "plot", "make_plan", "parse_name", "parse_values", "FAMILIES",
           "DEFAULT_OUTPUTS", *_STUDY_FILE_TOOLS]
