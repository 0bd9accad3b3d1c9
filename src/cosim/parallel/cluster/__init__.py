"""The Dask cluster a study runs on: which one (decided in one place), starting it, connecting, closing, stops.

Offers: ``choice.choose_cluster`` and ``ClusterChoice`` (a cluster file, a scheduler address or a local
cluster, checked), ``client.dask_client`` (a client on it, closed with what it started), ``local.local_cluster``,
``cluster_file.read_cluster_file`` and ``start_cluster`` (scale or adapt), ``early.EarlyCluster`` (the local
cluster started while a study is prepared), ``interrupts.stop_cleanly_on_signals`` (Ctrl-C and kill stop quietly),
``scheduler_check.scheduler_import_problem``.
"""
