"""Fixtures of the native FMU tests: the session's FMU folder, the plain C host compiled once, and the host's
environment with no Python in it. Helpers: native_fmu_support.py."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from native_fmu_support import compile_host


@pytest.fixture(scope="session")
def fmu_root(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fmu_native")


@pytest.fixture(scope="session")
def host(tmp_path_factory) -> Path:
    return compile_host(tmp_path_factory, "native_host.c", "-ldl", "-lpthread", "-lm")


@pytest.fixture(scope="session")
def no_python_env(tmp_path_factory) -> dict:
    """The whole environment of the C host: a PATH with nothing on it (no python), nothing else."""
    empty = tmp_path_factory.mktemp("empty_path")
    env = {"PATH": str(empty)}
    assert shutil.which("python3", path=env["PATH"]) is None and shutil.which("python", path=env["PATH"]) is None
    return env
