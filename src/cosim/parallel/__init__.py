"""Running points in parallel: the Dask cluster, the evaluator, point child processes, the dashboard pages.

Offers: ``point_stream.PointStream`` (points on Dask, rows back as they finish), ``isolation.IsolatedRunner`` and
``make_payload`` (points in child processes), ``cluster.start_cluster``.
"""
