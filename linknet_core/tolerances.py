"""The numerical tolerances and limits of the solver, in one place: the numpy reference reads them from here, and
linknet_core.native.model writes them into ln_model, so both paths decide by the same numbers (the native FMU
bakes them the same way). What each one decides, and why its value, is said beside it."""

# One cut decides "singular" everywhere (rank, self-stresses, minimum-norm solve, hypothesis (35)): an
# eigenvalue of A = C M^-1 C^T below SINGULAR_RCOND times the largest is zero. In terms of singular values
# of C that is sqrt(SINGULAR_RCOND) = 1e-5 relative.
SINGULAR_RCOND = 1e-10
# The cut of a position projection's Gauss-Newton retry, taken only where the iteration with SINGULAR_RCOND would
# fail: a flat braced cell pushed out of its plane has a near-self-stress whose eigenvalue (~(delta/R)^2 of the
# largest) falls below SINGULAR_RCOND, so Gauss-Newton never moves along it and stalls at a residual of ~delta^2/R.
# The minimum-norm solves of both paths cut the pivots of a completely pivoted Cholesky factorisation relative to A's
# largest diagonal entry (dynamics.tensions.MinNormSolver, native stages/minnorm.c). On the pushed triangulated net
# (tests/fmu_native) that direction's pivot was 1.5e-11..2.5e-11 of it at the start of a failing projection, and its
# eigenvalue fell to 6.5e-15 of the largest (2.3e-14 of the largest diagonal entry) at the iterates where a cut at
# 1e-13 stalled; the exact self-stresses' pivots sit at 1e-16..5e-16, a decade and more below this cut.
RETRY_SINGULAR_RCOND = 1e-14
PLANE_TOL = 1e-12  # an out-of-plane component at most this relative to its size is round-off (dropped in 2-D)
PIVOT_TOL = 1e-11  # a pivot below this times its diagonal entry means A is singular (every factorisation's rule)

# Newton on the position manifold (11): a residual within the round-off floor plus FLOOR_SAFETY times what the step
# leaves by construction is at the floor the conditioning allows (native/src/stages/projections.c uses the same rule)
FLOOR_SAFETY = 2.0
# ... but never above this many times the tolerance: far from (11) a redundant system can stall at a least-squares
# point off the manifold (its residual along a self-stress), which no round-off explains. Below the cap, the floor is
# what the conditioning allows: at a singular configuration (a taut string under gravity, a flat braced cell pushed
# out of its plane) a residual eps leaves a mass up to ~sqrt(2 eps) R off the exact position, which the run reports
# as the floor reached (benchmarks/stress.py checks the taut string's sag against it).
FLOOR_CAP_OVER_TOL = 1e4

# The error-controlled methods' step controller: the next step is the last times SAFETY err^(-1/(q+1)), kept within
# [MIN_FACTOR, MAX_FACTOR] of it
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0

# Sizes above which a dense computation gives way to a sparse one (links)
DENSE_RANK_LIMIT = 2500  # rank of G: above it, estimated from the LDL pivots
DENSE_MIN_NORM_LIMIT = 2500  # minimum-norm tensions: above it the redundant path uses MINRES (min-norm from x0 = 0)
