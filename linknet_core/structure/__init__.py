"""What a scene is, analysed once from its description: the class of its tension system (chain, tree,
general, redundant) and elimination order, its rank and self-stresses, its plane, its free rigid bodies."""
from linknet_core.tolerances import PLANE_TOL, RETRY_SINGULAR_RCOND, SINGULAR_RCOND
from linknet_core.structure.topology import (LinkPairs, Structure,
                                            analyse, constraint_jacobian, link_pairs, planar_normal,
                                            rank_and_nullspace)
from linknet_core.structure.bodies import BodyLayout, free_rigid_bodies
from linknet_core.structure.rigidity import BlockedFlex, second_order_rigid_flexes

__all__ = ["Structure", "analyse", "LinkPairs", "link_pairs", "constraint_jacobian", "rank_and_nullspace",
           "planar_normal", "SINGULAR_RCOND", "RETRY_SINGULAR_RCOND", "PLANE_TOL", "BodyLayout", "free_rigid_bodies",
           "BlockedFlex", "second_order_rigid_flexes"]
