"""Running points in parallel: the Dask cluster, the evaluator, point child processes, the dashboard pages.
"""
