"""Point isolation: each worker runs its points in a child process, so a point may hang or crash safely.

Offers: ``runner.IsolatedRunner`` (batches of points in a child, one row each, with a watchdog) and
``start_spare_children``, ``payload.make_payload`` (a system and its unit files, for a child anywhere),
``point_runner.PointRunner`` (the child's side: points on reused unit instances), ``child.child_main``,
``channel.Channel`` (the pipe back, read with deadlines), ``limits.recycle_reason`` (memory cap and recycling),
``children.kill_point_children_now`` (every child of this process), ``leftovers.remove_leftovers``.
"""
