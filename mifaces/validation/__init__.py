"""Validation of a fit on a simulated capture: the fitted faces against the true ones in a novel pose
under held-out lights and environments (:mod:`.validator`), and the fitted parameters and albedo
against the truth's (:mod:`.truth_errors`)."""
