"""How a fit ended: the statuses every stage reports, in one place.

Shape fits (:mod:`mifaces.shape`) end ``converged``, ``not_converged`` or
``diverged``; only a converged fit hands its vertices on. BRDF fits
(:mod:`mifaces.reflectance`) end as the Levenberg-Marquardt solver did
(``converged``, ``max_iterations``, ``stalled``), ``at_bound`` where the
optimum lies at the bound of a parameter's range, or ``prior`` where a region
took its BRDF from elsewhere (a neighbour, the defaults).
"""

#: The fit met its convergence test.
CONVERGED = "converged"
#: A shape fit that ran out of iterations or missed its tolerances.
NOT_CONVERGED = "not_converged"
#: A fit whose energy or parameters became non-finite or ran away.
DIVERGED = "diverged"
#: The solver used all its iterations.
MAX_ITERATIONS = "max_iterations"
#: The solver could not lower the loss any further for a reason other than convergence.
STALLED = "stalled"
#: A BRDF fit that converged with a parameter at the bound of its range.
AT_BOUND = "at_bound"
#: A region's BRDF taken from elsewhere rather than fitted.
PRIOR = "prior"

SHAPE_STATUSES = (CONVERGED, NOT_CONVERGED, DIVERGED)
BRDF_STATUSES = (CONVERGED, MAX_ITERATIONS, STALLED, AT_BOUND, PRIOR)
