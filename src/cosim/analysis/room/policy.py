"""The Content-Security-Policy of the decision room's pages: no script runs but bokeh's own.

Every text of a results folder reaches the page escaped (:mod:`.app`); this is the second wall, for the day
one is not.  A page of bokeh's server runs:

- its bundles, from the server's ``/static/js/`` (``'self'``);
- two inline scripts it writes into each page (the document's JSON and the call that draws it; they hold the
  session's token, so they differ per page): each is allowed by the SHA-256 of its own text, computed as the
  page is sent (:class:`ScriptPolicy`), so no other inline script and no inline event handler
  (``onerror=...``, which CSP allows only with ``'unsafe-inline'`` or ``'unsafe-hashes'``) runs;
- the code of its ``CustomJS`` callbacks, which BokehJS compiles with ``new Function``: ``'unsafe-eval'``.
  That code comes from this server's Python (the room's own), never from a results file.

Styles are left alone (bokeh sets element styles inline throughout).  Plug-ins (``object-src``), a changed
``<base>`` and framing by another site are refused.
"""

from __future__ import annotations

import base64
import hashlib
import re
from typing import Any

INLINE_SCRIPT = re.compile(rb"<script\b(?![^>]*\bsrc\s*=)[^>]*>(.*?)</script>", re.DOTALL | re.IGNORECASE)
FIXED = "object-src 'none'; base-uri 'none'; frame-ancestors 'none'"


def policy_for(page: bytes) -> str:
    """The Content-Security-Policy of an HTML ``page``: bokeh's scripts and the page's own inline scripts only."""
    hashes = sorted({"'sha256-" + base64.b64encode(hashlib.sha256(body).digest()).decode("ascii") + "'"
                     for body in INLINE_SCRIPT.findall(page)})
    return f"script-src 'self' 'unsafe-eval' {' '.join(hashes)}".rstrip() + "; " + FIXED


def script_policy() -> type:
    """A tornado OutputTransform (class) adding :func:`policy_for` to every response of the server; an HTML
    response sent in pieces (bokeh sends its pages whole) gets the policy of its first piece."""
    from tornado.web import OutputTransform

    class ScriptPolicy(OutputTransform):
        def transform_first_chunk(self, status_code: int, headers: Any, chunk: bytes, finishing: bool
                                  ) -> tuple[int, Any, bytes]:
            headers["Content-Security-Policy"] = policy_for(chunk) if headers.get(
                "Content-Type", "").startswith("text/html") else policy_for(b"")
            return status_code, headers, chunk

    return ScriptPolicy
