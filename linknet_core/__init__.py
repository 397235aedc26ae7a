"""linknet_core: networks of point masses joined by rigid links (seed: Peskin, 'Mechanics of a network of
rigid links with point masses at the vertices'). Knows nothing of FMI."""
from linknet_core.dynamics import Dynamics
from linknet_core.dynamics.interface_jacobian import InterfaceJacobian
from linknet_core.errors import ConsistencyError, LinknetError, SceneError, SolverError
from linknet_core.integrators import METHODS, make_integrator
from linknet_core.scene import Scene, builders, load_scene
from linknet_core.simulator import Result, RunSettings, Simulator, simulate
from linknet_core.state import State
from linknet_core.version import __version__
from linknet_core.ensemble import ensemble  # Dask, xarray and h5netcdf are imported only when a study runs

__all__ = ["Dynamics", "InterfaceJacobian", "Scene", "load_scene", "State", "Simulator", "simulate", "RunSettings", "Result", "METHODS",
           "make_integrator", "builders", "ensemble", "LinknetError", "SceneError", "ConsistencyError",
           "SolverError"]
