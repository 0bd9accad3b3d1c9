"""One run of one design point (:mod:`.run`, :mod:`.point`), and K points of one system in lock-step
(:mod:`.lockstep`).
"""
