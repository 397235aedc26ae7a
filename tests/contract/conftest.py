"""Shared by tests/contract: FMUs built once per session (tests/fmu_harness.py), the exit() host compiled once."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from fmu_harness import MODELS, ROOT, build_cached  # noqa: F401  (repo on sys.path)

CC = shutil.which("cc") or shutil.which("gcc")


@pytest.fixture(scope="session")
def contract_root(tmp_path_factory):
    return tmp_path_factory.mktemp("contract")


@pytest.fixture(scope="session")
def pendulum_fmu(contract_root):
    return build_cached(contract_root, str(MODELS / "pendulum.json"))


@pytest.fixture(scope="session")
def chain_fmu(contract_root):
    return build_cached(contract_root, str(MODELS / "chain_10.json"))


@pytest.fixture(scope="session")
def exit_host(contract_root):
    if CC is None:
        pytest.skip("no C compiler")
    exe = contract_root / "exit_host"
    subprocess.run([CC, "-O1", "-Wall", "-Werror", "-o", str(exe), str(ROOT / "tests/contract/exit_host.c"), "-ldl"],
                   check=True)
    return exe
