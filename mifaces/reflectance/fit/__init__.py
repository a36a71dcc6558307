"""The region fit: one BRDF model per face region (:mod:`.regions`), each by hierarchical
Levenberg-Marquardt on its samples (:mod:`.region_fit`) over the frozen residual problem
(:mod:`.problem`), in its parameter space (:mod:`.parameters`) with the solver
(:mod:`.levenberg_marquardt`); lobes the samples do not support (:mod:`.lobes`); and each fit's
parameter uncertainty (:mod:`.uncertainty`, with the albedo offsets' share in
:mod:`.offset_uncertainty` and the intervals in :mod:`.intervals`)."""
