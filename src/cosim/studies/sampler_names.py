"""The Optuna samplers ``cosim optimize`` offers, by name (``surrogate``: cosim's own, batch Bayesian
optimisation on the surrogates, :mod:`cosim.studies.surrogate_sampler`).

Apart from :mod:`cosim.studies.optimize` (which imports numpy, pandas and Optuna) so that the command line
can list them in ``--help`` and check ``--sampler`` without those imports (1.3 s of a 1.8 s ``--help``).
"""

SAMPLERS = ("tpe", "nsga2", "gp", "surrogate", "random", "qmc")
