"""The region fit: one BRDF model per face region by Levenberg-Marquardt (:mod:`.regions`),
its parameter space (:mod:`.parameters`), the solver (:mod:`.levenberg_marquardt`) and each
fit's parameter uncertainty (:mod:`.uncertainty`)."""
