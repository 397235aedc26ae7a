"""Where a benchmark writes, and how: under build/ unless asked to merge into the tracked docs/benchmarks.

A benchmark's results land in ``build/<name>`` (``build/<name>/quick`` for a reduced run); ``--merge`` writes them
into the tracked folder instead (``docs/benchmarks``, or a subfolder of it), where the published figures live;
``--out DIR`` chooses any other folder. Without ``--merge`` nothing is written or created under ``docs/``: an
``--out`` there is refused, so that a run meant for a look does not rewrite the published figures by accident.
(The one exception is deliberate: benchmarks.reference's cache of references in docs/benchmarks/references, a
tracked cache that the tests and CI read; see there.)

Every results file is written whole or not at all (``write_text``, ``write_with``: linknet_core.output.atomic_write),
so an interrupted run leaves the previous file, never half of a new one.

The path rules use the standard library only; linknet_core is imported by the writers alone.
"""
from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
TRACKED = DOCS / "benchmarks"
BUILD = ROOT / "build"


def _inside(path: Path, folder: Path) -> bool:
    path, folder = Path(path).expanduser().resolve(), folder.resolve()
    return path == folder or folder in path.parents


def checked(path, merge: bool = False, option: str = "--out", can_merge: bool = True,
            parser: argparse.ArgumentParser | None = None) -> Path:
    """``path`` as a Path, unless it lies inside the tracked docs/ and ``merge`` was not asked for: then the
    parser's error (exit 2), or without a parser a ValueError, naming the option and the rule (``can_merge``:
    whether the benchmark has a --merge to offer)."""
    path = Path(path)
    if not merge and _inside(path, DOCS):
        way = ("add --merge to update the published results, or choose a place outside docs/" if can_merge else
               "this benchmark publishes nothing there: choose a place outside docs/")
        message = (f"{option} {path}: inside the tracked {DOCS.relative_to(ROOT)}/, which a benchmark writes only "
                   f"with --merge ({way})")
        if parser is not None:
            parser.error(message)
        raise ValueError(message)
    return path


def output_dir(name: str, merge: bool, quick: bool = False, out=None, tracked: str = "",
               parser: argparse.ArgumentParser | None = None) -> Path:
    """The folder a benchmark writes its results into (not created here):

    * ``out`` (the user's --out) as given, refused inside docs/ without ``merge`` (``checked``);
    * with ``merge``: the tracked ``docs/benchmarks/<tracked>``;
    * otherwise ``build/<name>``, and ``build/<name>/quick`` for a ``quick`` run.
    """
    if out is not None:
        return checked(out, merge, parser=parser)
    if merge:
        return TRACKED / tracked if tracked else TRACKED
    return BUILD / name / "quick" if quick else BUILD / name


def build_path(name: str, out=None, option: str = "--out", parser: argparse.ArgumentParser | None = None) -> Path:
    """Where a benchmark that publishes nothing in docs/ writes (its results file or its work folder): ``out``
    (refused inside docs/, ``checked``), else ``build/<name>``."""
    return checked(out, option=option, can_merge=False, parser=parser) if out is not None else BUILD / name


def add_output_arguments(parser: argparse.ArgumentParser, name: str, tracked: str = "", quick: bool = False,
                         merge_detail: str = "") -> None:
    """--out DIR and --merge, with the help text that says where ``output_dir`` puts the results."""
    default = f"build/{name}" + ("[/quick]" if quick else "")
    target = f"{TRACKED.relative_to(ROOT)}" + (f"/{tracked}" if tracked else "")
    parser.add_argument("--out", type=Path, metavar="DIR",
                        help=f"output folder (default {default}; with --merge, {target}); inside docs/ only with "
                             "--merge")
    parser.add_argument("--merge", action="store_true",
                        help=f"write into the tracked {target} (or --out) instead of build/" +
                             (f": {merge_detail}" if merge_detail else ""))


def resolve(parser: argparse.ArgumentParser, args: argparse.Namespace, name: str, quick: bool = False,
            tracked: str = "") -> Path:
    """``output_dir`` for the arguments ``add_output_arguments`` added; a refused --out is the parser's error."""
    return output_dir(name, args.merge, quick=quick, out=args.out, tracked=tracked, parser=parser)


def write_with(path, write) -> Path:
    """``write(tmp)`` fills a temporary file next to ``path`` (same suffix), which then replaces ``path`` whole."""
    from linknet_core.output import atomic_write
    return atomic_write(path, write)


def write_text(path, text: str) -> Path:
    """``path`` holds ``text`` whole or is left as it was; missing folders are created."""
    return write_with(path, lambda tmp: Path(tmp).write_text(text))
