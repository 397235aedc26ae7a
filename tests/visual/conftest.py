"""Shared runs of the picture tests: real runs written as the CLI writes them, and a crafted motion whose
every link and tension is known (the helpers that look into pictures are in picture_probes.py)."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import visual


@pytest.fixture(scope="session")
def chain_npz(tmp_path_factory):
    """A 4-link chain released from horizontal (anchored at its first mass), 1 s, 41 samples, in the xz plane."""
    res = ln.simulate(ln.builders.chain(4, name="chain_4"), 1.0, method="rattle", dt=1e-3, n_out=41, progress=False)
    path = tmp_path_factory.mktemp("runs") / "chain_4.npz"
    res.save_npz(path)
    return path


@pytest.fixture(scope="session")
def net_npz(tmp_path_factory):
    """A 3 x 3 net anchored at two opposite corners, falling for 0.6 s: a motion in 3-D."""
    res = ln.simulate(ln.builders.net(3, 3), 0.6, method="rattle", dt=1e-3, n_out=31, progress=False)
    path = tmp_path_factory.mktemp("runs") / "net_3x3.npz"
    res.save_npz(path)
    return path


@pytest.fixture
def crafted():
    """A zigzag in the xz plane: A (anchored) - B - C - D, links A-B vertical, B-C horizontal, C-D vertical, so
    that no link's midpoint is near a mass, another link, the legend or the time stamp. Five samples 0.1 s
    apart; the free masses drift in x; link 1 pulls, link 2 pushes, link 3 pulls lightly."""
    base = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, -2.0]])
    n = 5
    X = np.repeat(base[None], n, axis=0)
    X[:, 1:, 0] += 0.05 * np.arange(n)[:, None]
    T = np.column_stack([np.linspace(9.0, 5.0, n), np.linspace(-7.0, -3.0, n), np.linspace(1.0, 3.0, n)])
    return visual.Motion(title="crafted", t=0.1 * np.arange(n), X=X, T=T, k1=np.array([0, 1, 2]),
                         k2=np.array([1, 2, 3]), fixed=np.array([True, False, False, False]),
                         mass_names=("A", "B", "C", "D"))
