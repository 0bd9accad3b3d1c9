"""The studies a user starts: a sweep of a design space, an optimisation, a sensitivity analysis.
"""
