"""One run of one design point (:mod:`.run`, :mod:`.point`), and K points of one system in lock-step
(:mod:`.lockstep`).

Offers: ``run.Execution`` and ``RunResult`` (one run), ``point.run_point`` (one design point), ``warm_up.warmed``,
``lockstep.LockstepRunner`` (K points in lock-step).
"""
