"""Fixtures of the decision-room tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.analysis.table import load_results


@pytest.fixture
def room(request):
    """A function (folder) -> the link of the room serving it; the servers stop after the test."""
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer

    servers = []

    def serve(folder: Path, **options) -> tuple[str, object]:
        server = RoomServer(Study(load_results(folder)), **options)
        servers.append(server)
        return server.link, server

    yield serve
    for server in servers:
        server.stop()
