"""linknet_core: networks of point masses joined by rigid links (seed: Peskin, 'Mechanics of a network of
rigid links with point masses at the vertices'). Knows nothing of FMI."""
from .dynamics import Dynamics
from .errors import ConsistencyError, LinknetError, SceneError, SolverError
from .integrators import METHODS, make_integrator
from .scene import Scene, load_scene
from .simulator import Result, Simulator, simulate
from .state import State
from . import builders
from .ensemble import ensemble  # Dask, xarray and h5netcdf are imported only when a study runs

__version__ = "0.1.0"

__all__ = ["Dynamics", "Scene", "load_scene", "State", "Simulator", "simulate", "Result", "METHODS",
           "make_integrator", "builders", "ensemble", "LinknetError", "SceneError", "ConsistencyError",
           "SolverError"]
