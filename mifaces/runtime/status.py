"""How a fit ended: the statuses every stage reports, in one place.

Shape fits (:mod:`mifaces.shape`) end ``converged``, ``not_converged`` or
``diverged``; only a converged fit hands its vertices on. BRDF fits
(:mod:`mifaces.reflectance`) end as the Levenberg-Marquardt solver did
(``converged``, ``max_iterations``, ``stalled``), ``at_bound`` where the
optimum lies at the bound of a parameter's range (or the lobe became a spike),
``at_start`` where the solver left the glossy parameters at their start
values, ``prior`` where a region took its BRDF from a fitted neighbour, or
``defaults`` where it took the model's default glossy parameters (no region
had a fit to lend: a skin fit that became a spike, a face with too few
samples). Only ``converged`` is a measurement to trust as it stands.
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
#: A BRDF fit whose glossy parameters the solver never moved from their start
#: values: those values are the start's, not a measurement.
AT_START = "at_start"
#: A region's BRDF taken from a fitted neighbour rather than fitted.
PRIOR = "prior"
#: A region's glossy parameters set to the model's defaults: neither fitted
#: nor taken from a fitted region.
DEFAULTS = "defaults"

SHAPE_STATUSES = (CONVERGED, NOT_CONVERGED, DIVERGED)
BRDF_STATUSES = (CONVERGED, MAX_ITERATIONS, STALLED, AT_BOUND, AT_START, PRIOR, DEFAULTS)
#: BRDF statuses of regions whose glossy parameters were not fitted to their own samples.
NOT_FITTED = (PRIOR, DEFAULTS)
