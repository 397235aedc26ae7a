"""Build the FMI 3.0 Co-Simulation FMU of a scene on the native C core (`build_fmu.py --native --fmi-version 3`).

The same model as the FMI 2.0 native FMU (fmu_src/native/build.py): the scene as data in resources/ by
build.scene_resource, the core and linknet_model.c through fmu_model.h, compiled once and cached by
build.compile_binaries, with the FMI 3.0 glue (fmi3Functions.c, the standard's headers in fmi3/) in place of the FMI 2.0
one. What differs is the variables: the Layout's scalars (fmu_src/linknet_fmu/layout.py, the one both FMI 2.0 FMUs
use) grouped into FMI 3 array variables, one per family the FMI 2.0 build defines (build.VARIABLE_FAMILIES): X and U
[masses with outputs,3], T [L], Freact [anchored,3], F [masses with inputs,3], P, V, A [input-driven anchors,3],
Jreact [driven,3], M [free], R [L], g [3], with <Dimension> elements; a table of them (fmi3_variables.h) is added to
the scene's resource.

    python3 fmu_src/native/build_fmi3.py models/chain_10.json -o chain_10_fmi3.fmu [--platforms host]
    python3 -m fmu_src.native.build_fmi3 models/chain_10.json -o chain_10_fmi3.fmu

Every option of build_fmu.py applies (its scene options are resolved there); build_fmi3_fmu is the function
build_fmu.py calls with what it resolved.
"""
from __future__ import annotations

import argparse
import datetime
import inspect
import shutil
import struct
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
for _path in (ROOT, HERE.parent):  # the checkout (build_fmu, linknet_core) and fmu_src (native.build, linknet_fmu)
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

from native import build  # noqa: E402  (the module build_fmu.py imports: one NativeBuildError)
from native.build import NativeBuildError  # noqa: E402

# the FMI 3 glue in sources/linknet/ in place of fmi2Functions.c; fmi2_api.h stays for the log categories it defines
FMI3_GLUE = ("fmi3Functions.c", "fmi3_variables.h", "fmu_states.h")
FMI3_HEADERS = ("fmi3PlatformTypes.h", "fmi3FunctionTypes.h", "fmi3Functions.h")  # the standard's, in fmi3/
FMI2_ONLY = ("fmi2Functions.c",)
# headers of the standard's that linknet_fmu_unit.h does not list: <stdbool.h> declares no function (only the macros
# bool, true, false), so the symbol hiding after it cannot touch it
HIDING_SAFE_HEADERS = {"stdbool.h"}

# build.py's binaries/ folders -> the FMI 3.0 platform tuples of their binaries (the macOS universal binary is split
# into its two thin slices, one per tuple)
FMI3_PLATFORMS = {"linux64": ("x86_64-linux",), "win64": ("x86_64-windows",),
                  "darwin64": ("x86_64-darwin", "aarch64-darwin"), "aarch64-linux": ("aarch64-linux",)}
MACH_O_CPU = {"x86_64-darwin": 0x01000007, "aarch64-darwin": 0x0100000C}  # CPU_TYPE_X86_64, CPU_TYPE_ARM64


@dataclass
class Variable:
    """One FMI 3 variable: `count` consecutive Layout value references from `first` (None: time), row-major."""

    name: str
    kind: str               # Float64 | String | Boolean; "time" for the independent variable
    causality: str
    variability: str
    initial: str | None
    declared_type: str | None
    description: str
    first: int | None
    shape: tuple            # () for a scalar
    vr: int = -1

    @property
    def count(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1


def _rows(items, what: str) -> str:
    """Which mass or link (``what``: "mass" or "link") each row is, 1-based as in the FMI 2.0 names: 'rows 1..10 are
    masses 2..11'."""
    numbers = [int(k) + 1 for k in items]
    plural = {"mass": "masses", "link": "links"}[what]
    if len(numbers) == 1:
        return f"row 1 is {what} {numbers[0]}"
    if numbers == list(range(numbers[0], numbers[0] + len(numbers))):
        return f"rows 1..{len(numbers)} are {plural} {numbers[0]}..{numbers[-1]}"
    return f"rows 1..{len(numbers)} are {plural} {', '.join(map(str, numbers))}"


def _mass_rows(masses) -> str:
    return _rows(masses, "mass")


def _link_rows(links) -> str:
    return _rows(links, "link")


def fmi3_variables(layout, cfg) -> list[Variable]:
    """The FMI 3 variables of a Layout, in value-reference order (0: time): each of the FMI 2.0 build's variable
    families (build.VARIABLE_FAMILIES) an array, its single Reals (build.SCALAR_VARIABLES) scalars, in the Layout's
    order, then the String and Boolean parameters. An array with no rows is left out (the FMI 2.0 FMUs have no scalar
    of it either)."""
    reals = []
    for family in build.VARIABLE_FAMILIES:
        vrs = np.asarray(getattr(layout, family.vrs), dtype=int)
        if vrs.size == 0:
            continue
        flat = vrs.ravel()
        if not np.array_equal(flat, np.arange(flat[0], flat[0] + flat.size)):
            raise NativeBuildError(f"the Layout's {family.name} value references are not consecutive: teach "
                                   "fmu_src/native/build_fmi3.py")
        v = layout.reals[int(flat[0])]
        rows = (f"; {_mass_rows(getattr(layout, family.masses))}" if family.masses is not None
                else f"; {_link_rows(getattr(layout, family.links))}" if family.links is not None else "")
        reals.append(Variable(family.name, "Float64", v.causality, v.variability, v.initial, v.declared_type,
                              family.description + rows, int(flat[0]), tuple(vrs.shape)))
    for attribute, _ in build.SCALAR_VARIABLES:
        vr = int(getattr(layout, attribute))
        v = layout.reals[vr]
        reals.append(Variable(v.name, "Float64", v.causality, v.variability, v.initial, v.declared_type,
                              v.description, vr, ()))
    out = [Variable("time", "time", "independent", "continuous", None, "Time", "simulation time", None, ())]
    out += sorted(reals, key=lambda v: v.first)
    out.append(Variable("integrator", "String", "parameter", "fixed", "exact", None,
                        "integration method: " + ", ".join(cfg["integrators"]), int(layout.integrator_vr), ()))
    out.append(Variable("estimate_error", "Boolean", "parameter", "fixed", "exact", None,
                        build.ESTIMATE_ERROR_DESCRIPTION, int(layout.estimate_error_vr), ()))
    for vr, v in enumerate(out):
        v.vr = vr
    return out


def add_variable_table(resource, variables) -> None:
    """fmi3_variables.h's table into the scene's resource (the entries fmi3.*, read by fmi3Functions.c)."""
    kinds = {"time": 0, "Float64": 1, "String": 2, "Boolean": 3}  # enum fmi3_variable_kind
    resource.add("fmi3.n_variables", "q", [len(variables)])
    resource.texts("fmi3.names", [v.name for v in variables])
    resource.add("fmi3.kind", "i", [kinds[v.kind] for v in variables])
    resource.add("fmi3.first", "q", [v.first or 0 for v in variables])
    resource.add("fmi3.count", "q", [v.count for v in variables])


# ---------------------------------------------------------------------------- modelDescription.xml
def _array_dependencies(variables, layout, deps: dict) -> dict:
    """FMI 3 variable name -> the value references of the variables its elements depend on (the Layout's scalar lists,
    each shared list counted once, mapped onto the arrays their elements belong to), in value-reference order."""
    vr_of = {v.name: v.vr for v in variables}
    out = {}
    for v in variables:
        if v.causality != "output":
            continue
        lists = {}
        for r in range(v.first, v.first + v.count):
            names = deps[layout.reals[r].name]
            lists[id(names)] = names
        arrays = {vr_of[name.split("[")[0]] for names in lists.values() for name in names}
        out[v.name] = sorted(arrays)
    return out


def model_description(cfg, layout, variables, guid: str, start_values: dict, experiment: dict, inv_mass,
                      directional: bool = True) -> bytes:
    """The FMI 3.0 modelDescription.xml; ``directional``: whether the FMU answers fmi3GetDirectionalDerivative (False
    where the scene's linearization is refused: the flag says so rather than every call failing)."""
    from linknet_fmu.layout import TYPES, UNITS
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    root = ET.Element("fmiModelDescription", dict(
        fmiVersion="3.0", modelName=cfg["model_identifier"], instantiationToken=guid,
        description=cfg["description"] + " FMI 3.0: the FMI 2.0 FMU's variables as arrays.",
        version=str(cfg.get("version", "1")), generationTool="linknet build_fmu.py --native --fmi-version 3",
        generationDateAndTime=now, variableNamingConvention="structured"))
    ET.SubElement(root, "CoSimulation", dict(
        modelIdentifier=cfg["model_identifier"], needsExecutionTool="false",
        canBeInstantiatedOnlyOncePerProcess="false",
        canGetAndSetFMUState="true", canSerializeFMUState="true", providesDirectionalDerivatives="true" if directional else "false",
        providesAdjointDerivatives="false", providesPerElementDependencies="false",
        canHandleVariableCommunicationStepSize="true", maxOutputDerivativeOrder="0", providesIntermediateUpdate="false",
        mightReturnEarlyFromDoStep="false", canReturnEarlyAfterIntermediateUpdate="false", hasEventMode="false",
        providesEvaluateDiscreteStates="false"))
    types_used = sorted({v.declared_type for v in variables if v.declared_type})
    units = ET.SubElement(root, "UnitDefinitions")
    for name in sorted({TYPES[t][1] for t in types_used}):
        ET.SubElement(ET.SubElement(units, "Unit", name=name), "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    typedefs = ET.SubElement(root, "TypeDefinitions")
    for name in types_used:
        ET.SubElement(typedefs, "Float64Type", name=name, quantity=TYPES[name][0], unit=TYPES[name][1])
    cats = ET.SubElement(root, "LogCategories")
    for name, text in build.log_categories(layout):
        ET.SubElement(cats, "Category", name=name, description=text.replace("fmi2", "fmi3"))
    ET.SubElement(root, "DefaultExperiment", {k: repr(float(x)) for k, x in experiment.items()})
    model_variables = ET.SubElement(root, "ModelVariables")
    for v in variables:
        attrs = dict(name=v.name, valueReference=str(v.vr), description=v.description, causality=v.causality,
                     variability=v.variability)
        if v.declared_type:
            attrs["declaredType"] = v.declared_type
        if v.kind in ("time", "Float64") and v.declared_type:
            attrs["unit"] = TYPES[v.declared_type][1]
        if v.initial:
            attrs["initial"] = v.initial
        if v.kind == "Boolean":
            attrs["start"] = "true" if cfg.get("error_estimate", True) else "false"
        elif v.kind == "Float64" and v.causality in ("input", "parameter"):
            attrs["start"] = " ".join(build._start(start_values[r]) for r in range(v.first, v.first + v.count))
        node = ET.SubElement(model_variables, "Float64" if v.kind == "time" else v.kind, attrs)
        if v.kind == "String":
            ET.SubElement(node, "Start", value=cfg["integrator"])
        for n in v.shape:
            ET.SubElement(node, "Dimension", start=str(n))
    structure = ET.SubElement(root, "ModelStructure")
    running = _array_dependencies(variables, layout, layout.dependencies(inv_mass))
    initial = _array_dependencies(variables, layout, layout.initial_dependencies(inv_mass))
    for tag, table in (("Output", running), ("InitialUnknown", initial)):
        for v in variables:
            if v.causality == "output":
                attrs = dict(valueReference=str(v.vr), dependencies=" ".join(map(str, table[v.name])))
                if table[v.name]:
                    attrs["dependenciesKind"] = " ".join("dependent" for _ in table[v.name])
                ET.SubElement(structure, tag, attrs)
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode").encode() + b"\n"


def build_description(ident: str, units: list[str]) -> bytes:
    """sources/buildDescription.xml (FMI 3.0): the files a tool compiles, sources/ the include folder, libm."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=ident)
    files = ET.SubElement(config, "SourceFileSet", language="C99",
                          compilerOptions="-ffp-contract=off -fno-math-errno")
    for name in units:
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(files, "IncludeDirectory", name=".")
    ET.SubElement(config, "Library", name="m", external="true", description="the C math library (libm), Unix only")
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode").encode() + b"\n"


# ---------------------------------------------------------------------------- sources/ and binaries/
def stage_fmi3_sources(dest: Path, ident: str) -> list[str]:
    """sources/ as build.stage_sources lays it out, with the FMI 3 glue in place of fmi2Functions.c; the units."""
    units = build.stage_sources(dest, ident)
    inner = dest / build.CORE_FOLDER
    for name in FMI2_ONLY:
        (inner / name).unlink()
        (dest / name).unlink()
        units.remove(name)
    for name in (n for n in FMI3_GLUE if n not in build.GLUE_FILES):  # the ones build.py does not stage already
        if (inner / name).exists():
            raise NativeBuildError(f"the core's sources now have a file named {name}, as the FMU glue does: rename one")
        shutil.copy2(HERE / name, inner / name)
    (inner / "fmi3").mkdir()
    for name in FMI3_HEADERS:
        shutil.copy2(HERE / "fmi3" / name, inner / "fmi3" / name)
    allowed = build._system_headers((HERE / build.UNIT_HEADER).read_text()) | HIDING_SAFE_HEADERS
    for p in [inner / n for n in FMI3_GLUE] + [inner / "fmi3" / n for n in FMI3_HEADERS]:
        extra = build._system_headers(p.read_text()) - allowed
        if extra:
            raise NativeBuildError(f"{p.name} includes <{'>, <'.join(sorted(extra))}>, which fmu_src/native/"
                                   f"{build.UNIT_HEADER} does not declare before hiding the FMU's symbols: add it "
                                   "there")
    unit = "fmi3Functions.c"
    (dest / unit).write_text(f"/* {build.CORE_FOLDER}/{unit}, compiled after {build.UNIT_HEADER} (see there). */\n"
                             f'#include "{build.UNIT_HEADER}"\n#include "{build.CORE_FOLDER}/{unit}"\n')
    units = sorted(units + [unit])
    (dest / "CMakeLists.txt").write_text(build.cmake_lists(ident, units))
    return units


def fmi3_platforms(spec) -> tuple[str, ...]:
    """build.py's folders to compile for a --platforms value: all, host, FMI 3.0 tuples (x86_64-linux,
    x86_64-windows, x86_64-darwin, aarch64-darwin, aarch64-linux) or build.py's own names."""
    if spec is None or spec in ("all", "host"):
        return build.platforms_from(spec)
    by_tuple = {t: folder for folder, tuples in FMI3_PLATFORMS.items() for t in tuples}
    items = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec) if s.strip()]
    return build.platforms_from([by_tuple.get(item, item) for item in items])


def thin_mach_o(universal: bytes, cpu: int) -> bytes:
    """The slice of CPU type ``cpu`` of a universal Mach-O (build.universal_mach_o's layout)."""
    magic, n = struct.unpack_from(">II", universal)
    if magic != build.FAT_MAGIC:
        raise NativeBuildError("the macOS binary is not a universal Mach-O: it cannot be split into FMI 3.0's folders")
    for i in range(n):
        cputype, _, offset, size, _ = struct.unpack_from(">iiIII", universal, 8 + 20 * i)
        if cputype == cpu:
            return universal[offset:offset + size]
    raise NativeBuildError(f"the macOS universal binary has no slice of CPU type {cpu:#x}")


def fmi3_binaries(built: dict) -> dict[str, bytes]:
    """binaries/<FMI 3.0 tuple>/<file> -> bytes, from build.compile_binaries' folders."""
    out = {}
    for folder, binary in built.items():
        for tuple_ in FMI3_PLATFORMS[folder]:
            data = binary.read_bytes()
            out[f"{tuple_}/{binary.name}"] = thin_mach_o(data, MACH_O_CPU[tuple_]) if tuple_ in MACH_O_CPU else data
    return out


def build_fmi3_fmu(scene, cfg: dict, layout, out: Path, experiment: dict, quiet: bool = False,
                   platforms=None) -> Path:
    """Write the FMI 3.0 native FMU of ``scene`` to ``out``; the arguments are build.build_native_fmu's (without the
    FMI 2.0 model description's postprocess); ``platforms`` as fmi3_platforms takes them."""
    import time
    started = time.perf_counter()
    out = Path(out)
    folders = fmi3_platforms(platforms)
    build.check_settings(cfg)
    resource, facts = build.bake(scene, cfg, layout)
    variables = fmi3_variables(layout, cfg)
    add_variable_table(resource, variables)
    ident = cfg["model_identifier"]
    resource_name, _ = build.resource_format()
    with tempfile.TemporaryDirectory(prefix="linknet_fmi3_fmu_") as tmp:
        tmp = Path(tmp)
        sources = tmp / "fmu" / "sources"
        units = stage_fmi3_sources(sources, ident)
        (sources / "buildDescription.xml").write_bytes(build_description(ident, units))
        # the sources differ from FMI 2.0's: another GUID, and states the FMI 2.0 FMU refuses
        data, guid = build.with_identity(resource, build.sources_digest(sources))
        binaries = fmi3_binaries(build.compile_binaries(sources, units, ident, folders, tmp / "binaries"))
        md = model_description(cfg, layout, variables, guid, build.start_values(scene, cfg, layout), experiment,
                               scene.inv_mass, directional=not facts["linearization_refusal"])
        build.pack(out, {"modelDescription.xml": md, **{f"binaries/{n}": d for n, d in sorted(binaries.items())},
                         **build.sources_files(sources), f"resources/{resource_name}": data})
    if not quiet:
        arrays = ", ".join(f"{v.name} {list(v.shape)}" for v in variables if v.shape)
        print(f"built {out} (FMI 3.0 native model {ident}: arrays {arrays}; {facts['specialisation']} specialisation; "
              f"binaries for {', '.join(sorted({n.split('/')[0] for n in binaries}))}; {out.stat().st_size / 1024:.0f} "
              f"KiB; {time.perf_counter() - started:.1f} s)")
    return out


# ---------------------------------------------------------------------------- command line
def build_scene_fmi3(scene_path, out=None, platforms=None, **options) -> Path:
    """The FMI 3.0 FMU of a scene file, build_fmu.build_scene_fmu's options (integrator, step, tolerance, inputs,
    outputs, stop_time, comm_step, error_estimate, quiet) resolved by it as for its FMI 2.0 native FMU."""
    import build_fmu
    accepted = inspect.signature(build_fmu.build_scene_fmu).parameters
    if platforms is not None and "platforms" in accepted:
        options["platforms"] = platforms
    if "fmi_version" in accepted:
        return build_fmu.build_scene_fmu(scene_path, out, native=True, fmi_version=3, **options)
    # a build_fmu.py without --fmi-version: it resolves the scene's options and hands them to the native build, which
    # is this module's for the call
    fmi2_build = build.build_native_fmu

    def fmi3_build(scene, cfg, layout, out, experiment, postprocess, quiet=False, platforms=None):
        return build_fmi3_fmu(scene, cfg, layout, out, experiment, quiet=quiet, platforms=platforms)

    build.build_native_fmu = fmi3_build
    try:
        return build_fmu.build_scene_fmu(scene_path, out, native=True, **options)
    finally:
        build.build_native_fmu = fmi2_build


def main(argv=None):
    p = argparse.ArgumentParser(description="Build the FMI 3.0 Co-Simulation FMU of a linknet scene on the native C "
                                "core (array variables; no Python on the host).")
    p.add_argument("scene", help="scene file (JSON)")
    p.add_argument("-o", "--output", help="FMU path (default: <scene name>.fmu)")
    p.add_argument("--integrator")
    p.add_argument("--step", type=float)
    p.add_argument("--tolerance", type=float)
    p.add_argument("--inputs", help="masses with force inputs: 1-based numbers or names, comma-separated (default: "
                   "every free mass)")
    p.add_argument("--outputs", help="masses with position and velocity outputs: 1-based numbers or names, "
                   "comma-separated (default: all)")
    p.add_argument("--stop-time", type=float)
    p.add_argument("--comm-step", type=float)
    p.add_argument("--no-error-estimate", action="store_true")
    p.add_argument("--platforms", metavar="LIST", help="all, host, or FMI 3.0 platform tuples, comma-separated")
    a = p.parse_args(argv)
    build_scene_fmi3(a.scene, a.output, platforms=a.platforms, integrator=a.integrator, step=a.step,
                     tolerance=a.tolerance, inputs=a.inputs, outputs=a.outputs, stop_time=a.stop_time,
                     comm_step=a.comm_step, error_estimate=False if a.no_error_estimate else None)


if __name__ == "__main__":
    main()
