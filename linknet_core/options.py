"""One validated argparse type per command-line option, for every command (linknet's subcommands and build_fmu.py).

Every option that takes a value is parsed by one of these (or by argparse's `choices`): a bad value is answered at
once, naming the option and its rule, before anything is computed (tests/contract checks every option of every
parser). Each is marked with the rule it applies. Light: nothing heavy is imported until a value is checked.
"""
from __future__ import annotations

import argparse
import math
import os
import tempfile
import re
from pathlib import Path

from linknet_core.errors import LinknetError

def validated(rule: str):
    def mark(convert):
        convert.rule = rule
        convert.__name__ = rule  # argparse names the type in "invalid <name> value" messages
        return convert
    return mark


def _float_text(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


@validated("positive number")
def positive_number(text: str) -> float:
    from linknet_core.integrators import positive_problem

    x = _float_text(text)
    if positive_problem(x):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive finite number")
    return x


@validated("relative tolerance")
def relative_tolerance(text: str) -> float:
    from linknet_core.integrators import RTOL_MAX, RTOL_MIN, rtol_problem

    x = _float_text(text)
    if rtol_problem(x):
        raise argparse.ArgumentTypeError(f"{text!r} must lie in [{RTOL_MIN:g}, {RTOL_MAX:g}) "
                                         "(a relative tolerance)")
    return x


@validated("sample count")
def sample_count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if n < 2:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 2 (the samples at t = 0 and at --t-end)")
    return n


@validated("readable file")
def readable_file(text: str) -> str:
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text!r} is not a file" + ("" if path.exists() else " (it does not exist)"))
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} cannot be read (permissions)")
    return text


def writable_path_problem(text: str) -> str | None:
    """Why a file could not be written at path `text` (None if it can): a folder there, an ancestor that is a file,
    or no write permission on the nearest existing folder (missing folders are created when writing)."""
    path = Path(os.path.abspath(Path(text).expanduser()))
    if str(text).strip() == "":
        return "is empty"
    if path.is_dir():
        return "is a folder"
    if path.exists():
        return None if os.access(path, os.W_OK) else "exists and cannot be overwritten (permissions)"
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"cannot be created: {parent} is not a folder"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"cannot be created: no write permission in {parent}"
    # permission bits do not tell everything (root passes access() on /proc, a read-only mount, a full quota):
    # try the write itself, with a file of our own beside the target, removed at once
    try:
        fd, probe = tempfile.mkstemp(prefix=".linknet-write-check-", dir=parent)
    except OSError as exc:
        return f"cannot be created in {parent}: {exc.strerror or exc}"
    os.close(fd)
    os.unlink(probe)
    return None


def _output(suffixes: tuple, what: str):
    @validated(f"writable {what} path")
    def convert(text: str) -> str:
        problem = writable_path_problem(text)
        if problem:
            raise argparse.ArgumentTypeError(f"{text!r} {problem}")
        if suffixes and Path(text).suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text!r}: {what} is written as {' or '.join(suffixes)}")
        return text
    return convert


npz_path = _output((".npz",), "the result arrays file")
plot_path = _output((".png", ".pdf", ".svg"), "the plot")


# argparse reads "-1e-3" as an option name (its number pattern has no exponent) and answers "expected one
# argument"; with this pattern a negative number is a value, which its option's type then refuses by its rule.
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|nan)$", re.IGNORECASE)


def one_line_errors(parser: argparse.ArgumentParser) -> None:
    """argparse prints a usage block before a bad option's error; the CLI answers with one line naming the problem
    (for the parser and its subcommands)."""
    def error(message):
        parser.exit(2, f"{parser.prog}: error: {message} (see {parser.prog} --help)\n")
    parser.error = error
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                one_line_errors(sub)


def _numbers_may_be_negative(parser: argparse.ArgumentParser) -> None:
    parser._negative_number_matcher = _NEGATIVE_NUMBER
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _numbers_may_be_negative(sub)


@validated("finite number")
def finite_number(text: str) -> float:
    x = _float_text(text)
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number")
    return x


def whole_number(minimum: int):
    """Whole numbers from `minimum` on."""
    @validated(f"whole number >= {minimum}")
    def convert(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"{text!r} must be at least {minimum}")
        return n
    return convert


count = whole_number(1)


@validated("random seed")
def random_seed(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if not 0 <= n < 2**64:
        raise argparse.ArgumentTypeError(f"{text!r} must lie in [0, 2**64) (a random seed)")
    return n


def readable_file_with(suffixes: tuple, what: str):
    @validated(f"readable {what}")
    def convert(text: str) -> str:
        readable_file(text)
        if Path(text).suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text!r}: {what} is a {' or '.join(suffixes)} file")
        return text
    return convert


def text_with(rule: str, pattern: str, example: str):
    """Text whose form is checked here (its meaning later, against the scene): `pattern` a regular expression."""
    form = re.compile(pattern)

    @validated(rule)
    def convert(text: str) -> str:
        if not form.fullmatch(text.strip()):
            raise argparse.ArgumentTypeError(f"{text!r} is not {rule}, e.g. {example}")
        return text.strip()
    return convert
