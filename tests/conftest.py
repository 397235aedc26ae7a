"""Shared by every test folder: the repository's folders on sys.path (the shared scene builders of
scene_builders.py, the FMU harness, build_fmu.py and the benchmarks), and fixtures for the shipped scenes."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
for folder in (ROOT, TESTS):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
# the suite's native FMUs carry this machine's binary only (build_fmu.py --native --platforms host), built faster;
# tests/fmu_native/test_native_platforms.py builds and checks every platform's
os.environ.setdefault("LINKNET_FMU_PLATFORMS", "host")

import linknet_core as ln  # noqa: E402

MODELS = ROOT / "models"


@pytest.fixture(scope="session")
def models_dir() -> Path:
    return MODELS


@pytest.fixture(scope="session")
def shipped_scene():
    """The shipped scene of that name (models/NAME.json), loaded once per session."""
    loaded = {}

    def load(name: str) -> ln.Scene:
        if name not in loaded:
            loaded[name] = ln.load_scene(MODELS / f"{name}.json")
        return loaded[name]
    return load
