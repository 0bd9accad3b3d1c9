"""The Dask dashboard of the local cluster cosim starts, loaded when a browser first asks for it.

Distributed builds its dashboard (bokeh and its pages) while the scheduler
starts: about 0.3-0.4 s of the client's CPU (2-core box), a sixth of the
README's main job, paid by every sweep whether anyone looks or not.  The
local cluster therefore starts its scheduler with the web server but without
the dashboard pages (``Scheduler(dashboard=False)``; the server's own routes,
``/health``, ``/metrics``, ``/sitemap.json``, ... answer as before), and
:func:`serve_dashboard_on_demand` adds a handler for every other path: the
first request there loads the dashboard (:func:`distributed.dashboard.scheduler.connect`,
what the scheduler would have done at start), removes the handler, calls
``dashboard_loaded(scheduler)`` of the scheduler plugins that have it
(:class:`cosim.parallel.dashboard.points.PointsPlugin` links its page from the
navigation bar) and redirects the browser to the same address, now served by
the dashboard.  The
link printed when a sweep starts is the same; its first opening takes about
half a second longer.
"""

from __future__ import annotations

import asyncio
import importlib
from typing import Any

DASHBOARD_MODULE = "distributed.dashboard.scheduler"


def dashboard_available() -> bool:
    """Whether bokeh is installed (distributed serves its dashboard only with it); found, not imported."""
    import importlib.util

    return importlib.util.find_spec("bokeh") is not None


def serve_dashboard_on_demand(cluster: Any) -> None:
    """Make ``cluster``'s scheduler (in this process, started without its dashboard) load it when first opened."""
    from tornado import web

    scheduler = cluster.scheduler
    loader = web.Application()
    state: dict[str, Any] = {"loading": None}

    async def load() -> None:
        # the import (~0.3 s of CPU) runs in a thread, so the scheduler's loop goes on meanwhile
        module = await asyncio.get_running_loop().run_in_executor(None, importlib.import_module, DASHBOARD_MODULE)
        application = scheduler.http_application
        if loader in application.applications:
            application.applications.remove(loader)
            module.connect(application, scheduler.http_server, scheduler, prefix="/")
            for plugin in list(scheduler.plugins.values()):  # e.g. the points page's link in the navigation bar
                hook = getattr(plugin, "dashboard_loaded", None)
                if callable(hook):
                    hook(scheduler)

    class LoadDashboard(web.RequestHandler):
        async def get(self, *args: Any) -> None:
            if state["loading"] is None:
                state["loading"] = asyncio.ensure_future(load())
            await asyncio.shield(state["loading"])  # several first requests share one load
            self.redirect(self.request.uri)  # now served by the dashboard (or its own 404)

    loader.add_handlers(r".*", [(r"/.*", LoadDashboard)])
    scheduler.http_application.add_application(loader)  # a list append: safe from this thread
