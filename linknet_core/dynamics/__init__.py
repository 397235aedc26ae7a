"""The numpy reference of the physics: the forces F_k of (9), the tension system (25)-(26) and its solvers,
the accelerations (9) and the projections onto (11)-(12). The native core (linknet_core.native) is the fast
path; the tests hold the two together to round-off."""
from linknet_core.dynamics.equations import Dynamics

__all__ = ["Dynamics"]
