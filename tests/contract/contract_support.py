"""Helpers of tests/contract, importable by name (a conftest module's name is shared by every test folder)."""
from __future__ import annotations

import zipfile

from fmu_harness import MODELS, ROOT  # noqa: F401  (re-exported for the tests)


def extract(fmu, where):
    """Unzip an FMU once; returns (folder, model identifier, guid)."""
    from fmpy import read_model_description
    md = read_model_description(str(fmu))
    if not where.exists():
        with zipfile.ZipFile(fmu) as z:
            z.extractall(where)
    return where, md.coSimulation.modelIdentifier, md.guid
