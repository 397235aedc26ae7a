"""Errors raised by linknet. Every message names the offending mass, link or variable and the rule."""


class LinknetError(ValueError):
    """Base class of every error linknet raises on bad input or an impossible state."""


class SceneError(LinknetError):
    """The scene description breaks a rule (unknown mass, self-link, bad mass or length, ...)."""


class ConsistencyError(LinknetError):
    """The state admits no consistent accelerations: hypothesis (35) of the seed is violated."""


class SolverError(LinknetError):
    """The integration cannot continue from the current state (step too small, non-finite values, ...)."""
