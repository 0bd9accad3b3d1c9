"""Running points in parallel: the evaluate loop on Dask, the cluster, point isolation, the dashboard pages.

Offers: ``point_stream.PointStream`` (points on Dask, rows back as they finish), ``tasks.run_batch`` (the one
task function), ``reruns.Reruns`` (the points of a task lost with its workers), ``scattered.ScatteredPayload``
(the payload on every worker), and the folders ``cluster`` (which cluster, starting and closing it, stops),
``isolation`` (points in child processes: pipes, limits) and ``dashboard`` (the dashboard pages).
"""
