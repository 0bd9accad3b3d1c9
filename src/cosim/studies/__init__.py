"""The studies a user starts: one runner over point sources (a design grid, an optimiser, a sensitivity design).

Offers: ``runner.Study`` (the one run sequence of every study) and ``PointSource`` (what a source provides),
``options.Where``, ``How``, ``Stop``, ``Show`` (a study's options, four typed records) and ``split_options``;
the sources ``sweep.DesignGrid`` (front door ``Sweep``), ``optimize.Optimiser`` (front door ``Optimization``),
``sensitivity.SensitivityStudy`` (SALib's sample on a grid); ``driver.StudyFolder`` and ``study_cluster`` (the
folder and the cluster of a study).
"""
