"""The studies a user starts: a sweep of a design space, an optimisation, a sensitivity analysis.

Offers: ``sweep.Sweep``, ``optimize.Optimization``, ``sensitivity.SensitivityStudy``; ``driver.StudyFolder`` and
``driver.study_cluster`` (what every study does with its folder and cluster).
"""
