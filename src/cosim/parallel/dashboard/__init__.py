"""The Dask dashboard pages of a study: its tasks' names, the points page, loading on demand, a quiet web server.

Offers: ``task_keys.task_key`` and ``task_keys.payload_key`` (what the progress bars show), ``points.open_board`` (the ``/cosim`` page counting
points), ``on_demand.serve_dashboard_on_demand`` and ``dashboard_available``, ``web_server.web_server_tracebacks_as_lines``.
"""
