"""Fixtures of the analysis tests."""

from __future__ import annotations

import os
import select
import subprocess

import pytest

from tests.helpers.tools import require_tool


@pytest.fixture(scope="module")
def xvfb(tmp_path_factory):
    """A private Xvfb display; yields (display, framebuffer XWD file).

    Xvfb picks the display number itself (``-displayfd``: it takes the first free one, claiming it with its lock
    file, and writes the number to the pipe once it accepts connections): a number chosen here by looking for a
    free one could be taken by another Xvfb started at the same moment (another pytest worker or test run).
    """
    require_tool("Xvfb", "xvfb")
    fbdir = tmp_path_factory.mktemp("xvfb")
    ready, ready_w = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(ready_w), "-screen", "0", "1280x1024x24", "-nolisten", "tcp",
                             "-fbdir", str(fbdir)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            pass_fds=(ready_w,))
    os.close(ready_w)
    with os.fdopen(ready) as pipe:
        waited, _, _ = select.select([pipe], [], [], 15)
        number = pipe.readline().strip() if waited else ""
    if not number.isdigit():
        proc.kill()
        pytest.fail(f"Xvfb did not start: {proc.stderr.read().decode()[-500:]}")
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{number}"
    yield f":{number}", fbdir / "Xvfb_screen0"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    proc.wait(timeout=10)
