"""The decision room: ``cosim explore DIR`` serves a study as a Bokeh server app in the browser.

- :mod:`.data`: the columns the views draw, from a :class:`cosim.analysis.decision.Decision` (no bokeh);
- :mod:`.views`: the bokeh figures, tables and widgets;
- :mod:`.app`: one browser tab's document: the views wired to its Decision;
- :mod:`.server`: the Bokeh server on loopback (or a host with a token in the link).

Nothing here is imported by ``import cosim``: bokeh is imported when the room is served.
"""
