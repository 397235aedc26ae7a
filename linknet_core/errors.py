"""Errors raised by linknet. Every message names the offending mass, link or variable and the rule."""


class LinknetError(ValueError):
    """Base class of every error linknet raises on bad input or an impossible state."""


class SceneError(LinknetError):
    """The scene description breaks a rule (unknown mass, self-link, bad mass or length, ...)."""


class ConsistencyError(LinknetError):
    """The state admits no consistent accelerations: hypothesis (35) of the seed is violated."""


class SolverError(LinknetError):
    """The integration cannot continue from the current state (step too small, non-finite values, ...)."""


# A residual that stalled within this factor of the floor its last Newton step allowed stalled at that floor.
NEAR_FLOOR = 4.0


def projection_failure(where: str, reached: float, before: float, floor: float) -> str:
    """Why the position projection onto the link lengths (11) failed, in words, and what may help: one message
    for the numpy reference and the native core. ``reached``: the relative residual the iteration ended at;
    ``before``: the largest relative violation before projection; ``floor``: the relative floor its last Newton
    step allowed (the round-off floor plus what that step left by construction; 0: no Newton step taken).

    At the floor the linear model itself cannot remove the residual (a singular or badly conditioned Newton
    matrix): a smaller step does not help. Above it the linear model would remove the residual but the step
    does not: the iteration is outside Newton's region of convergence, which shrinks with the step."""
    head = (f"position projection onto the link lengths (11) did not converge {where} (it was {before:.3g} "
            "relative before projection)")
    if floor > 0 and reached <= NEAR_FLOOR * floor:
        return (f"{head}: it stalls at the floor this configuration allows ({floor:.3g} relative): the links' "
                "Newton matrix is singular or badly conditioned here (a taut string, a loop passing a flat "
                "position, extreme mass ratios), so a smaller step cannot help. Change the configuration or the "
                "masses")
    return (f"{head}: Newton's linear model would remove the residual but its steps do not (the step is too large "
            "for this configuration's nonlinearity, e.g. fast motion of light masses between heavy ones). Reduce "
            "the step (or use an adaptive method, which chooses its own)")
