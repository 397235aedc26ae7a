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
# h omega above which an explicit step (RATTLE is Stormer-Verlet on the links' manifold) amplifies an oscillation
# of angular frequency omega instead of following it: a 1e12 mass-ratio chain hanging at rest runs at h omega = 1.95
# and fails at 2.05 with omega from equations.fastest_oscillation.
STABILITY_LIMIT = 2.0
# A failed step's omega is estimated from the tensions at its start, one moment of an oscillation that has grown and
# swings the tensions with it, so it can read low: falling chains of mass ratio 1e9 and 1e12 failed with h omega
# read between 0.8 and 200 (RATTLE and its compositions, dt 1e-3 .. 1e-6). So a failure beyond STABILITY_LIMIT /
# READS_LOW is put down to the step, and the advice keeps that margin.
READS_LOW = 4.0


def projection_failure(where: str, reached: float, before: float, floor: float, *, dt: float = 0.0,
                       stage_fraction: float = 1.0, omega: float = 0.0) -> str:
    """Why the position projection onto the link lengths (11) failed, in words, and what may help: one message
    for the numpy reference and the native core. ``reached``: the relative residual the iteration ended at;
    ``before``: the largest relative violation before projection; ``floor``: the relative floor its last Newton
    step allowed (the round-off floor plus what that step left by construction; 0: no Newton step taken).
    A fixed-step method also gives its ``dt``, its largest stage step over dt (``stage_fraction``, max |gamma_i|
    of a composition) and ``omega``, the fastest oscillation of its masses at the start of the step that failed
    (:func:`linknet_core.dynamics.equations.fastest_oscillation`).

    Beyond the stability limit (h omega > 2 for the largest stage step h; READS_LOW is the estimate's margin) the
    steps amplify that oscillation: light masses between tensioned links (extreme mass ratios) are thrown off (11)
    further every step until no projection converges, and the step, not the configuration, is the cause, whatever
    the iteration's floor.
    Below it: at the floor the linear model itself cannot remove the residual (a singular or badly conditioned
    Newton matrix), so a smaller step does not help; above the floor the linear model would remove the residual
    but the step does not: the iteration is outside Newton's region of convergence, which shrinks with the
    step."""
    head = (f"position projection onto the link lengths (11) did not converge {where} (it was {before:.3g} "
            "relative before projection)")
    h = stage_fraction * dt
    if h * omega > STABILITY_LIMIT / READS_LOW:
        stage = "" if stage_fraction == 1.0 else f" (its largest stage, {stage_fraction:.3g} dt)"
        safe = STABILITY_LIMIT / READS_LOW
        return (f"{head}: the step exceeds the stability limit of explicit steps here: h omega = {h * omega:.3g}, "
                f"for the step h = {h:.3g} s{stage} and omega = {omega:.3g} rad/s, the fastest oscillation of a "
                "mass between its tensioned links, estimated at the start of the step that failed. The limit is "
                f"h omega = {STABILITY_LIMIT:g}; once the oscillation has grown the estimate can read up to "
                f"{READS_LOW:g} times low, and omega grows with the tensions as the motion goes on. Use dt below "
                f"{safe / (stage_fraction * omega):.3g} s (h omega = {safe:g}) or an adaptive method (dop853), "
                "which follows omega")
    if floor > 0 and reached <= NEAR_FLOOR * floor:
        return (f"{head}: it stalls at the floor this configuration allows ({floor:.3g} relative): the links' "
                "Newton matrix is singular or badly conditioned here (a taut string, a loop passing a flat "
                "position, extreme mass ratios), so a smaller step cannot help. Change the configuration or the "
                "masses")
    return (f"{head}: Newton's linear model would remove the residual but its steps do not (the step is too large "
            "for this configuration's nonlinearity, e.g. fast motion of light masses between heavy ones). Reduce "
            "the step (or use an adaptive method, which chooses its own)")
