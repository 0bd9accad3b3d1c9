"""Issue 28.6: `cosim explore` ends promptly on Ctrl-C, SIGTERM and SIGHUP, quietly, exit 130 as every command.

Real processes, real signals: the decision room's web server with a page open in chromium, and the Tk window
(`--tk`, on a private Xvfb) while its arm animation runs and while a re-run is under way.  Ctrl-C is SIGINT to
the process group, as a terminal sends it.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.analysis.test_analysis_explorer import linear_ode_sweep
from tests.analysis.test_analysis_traces import PICK_AND_PLACE, robot_table
from tests.helpers.paths import HELPERS, REPO

SRC = REPO / "src"
PROMPT = 10.0  # seconds: a stop that takes longer than this is not prompt (it takes well under 1 s here)


def env() -> dict[str, str]:
    """This checkout's cosim, and the display the xvfb fixture set (it sets DISPLAY when the test starts)."""
    return dict(os.environ, PYTHONPATH=str(SRC))


def send(proc: subprocess.Popen, how: str) -> None:
    if how == "SIGINT":
        os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole process group
    else:
        proc.send_signal(getattr(signal, how))


def ended(proc: subprocess.Popen) -> tuple[int, str, float]:
    """(exit code, stderr, seconds it took to end) of a process just signalled; killed if it does not end."""
    start = time.monotonic()
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        pytest.fail(f"cosim explore did not end within 60 s of the signal: {err[-2000:]}")
    return proc.returncode, err, time.monotonic() - start


def refused(link: str) -> bool:
    host, port = link.split("//")[1].split("/")[0].rsplit(":", 1)
    with socket.socket() as s:
        s.settimeout(5)
        return s.connect_ex((host, int(port))) != 0


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_the_room_server_with_a_page_open_stops_on_a_signal(tmp_path, write_spec, browser, how):  # noqa: F811
    from cosim.analysis.room import browser as B

    folder = linear_ode_sweep(tmp_path / "decay", write_spec).parent
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "explore", str(folder)], env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    line = proc.stdout.readline()
    assert " is at http://127.0.0.1:" in line, line
    link = line.split(" is at ")[1].split()[0]
    count, _ = B.load(browser, link)  # a page with its live websocket session
    assert count.startswith("<b>3</b> of 3 designs")
    send(proc, how)
    code, err, took = ended(proc)
    assert code == 130, err
    assert err.strip().splitlines()[-1] == "cosim: interrupted", err
    assert "Traceback" not in err and "ERROR" not in err, err
    assert took < PROMPT, took
    assert refused(link)  # the port is closed: the server is gone, not left in the background


def tk_explorer(folder: Path, when: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(HELPERS / "explore_tk_driver.py"), f"--when={when}",
                             "explore", "--tk", str(folder)], env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    line = proc.stdout.readline()
    if line.strip() != "ready":
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail(f"the explorer did not get ready: {line!r} {proc.communicate()[1][-2000:]}")
    return proc


@pytest.mark.parametrize("how", ["SIGINT", "SIGTERM"])
def test_the_tk_window_stops_on_a_signal_during_its_animation(xvfb, tmp_path, panda_viewer, how):  # noqa: F811
    """Before, a Ctrl-C during the animation landed in one of its timer callbacks: tkinter printed the
    KeyboardInterrupt's traceback and went on (only kill -9 ended it).  Three presses, 0.2 s apart, as an
    impatient user does: the first ends it, none prints a traceback."""
    if not PICK_AND_PLACE.exists():
        pytest.skip("examples/pick_and_place/spec.json is not there")
    proc = tk_explorer(robot_table(tmp_path / "pp").parent, "animating")
    start = time.monotonic()
    for _ in range(3):
        if proc.poll() is None:
            send(proc, how)
            time.sleep(0.2)
    code, err, _ = ended(proc)
    took = time.monotonic() - start
    # the first signal ends the command (130); a later press while the process exits ends it at once: cosim's
    # last handler exits with 128 + the signal's number (130 for Ctrl-C, 143 for SIGTERM), as a shell shows a
    # process a signal ended; a press in the interpreter's last milliseconds, after Python has given the signals
    # back their default action, ends it by the signal itself (Popen says -N, a shell says 128 + N as well)
    signum = getattr(signal, how)
    assert code in (130, 128 + signum, -signum), err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Exception in Tkinter" not in err, err
    assert took < PROMPT, took


def test_the_tk_window_stops_on_ctrl_c_during_a_rerun(xvfb, tmp_path, panda_viewer):  # noqa: F811
    if not PICK_AND_PLACE.exists():
        pytest.skip("examples/pick_and_place/spec.json is not there")
    proc = tk_explorer(robot_table(tmp_path / "pp").parent, "rerun")
    time.sleep(0.6)  # the re-run (about a second here) started 0.3 s after 'ready'
    send(proc, "SIGINT")
    code, err, took = ended(proc)
    assert code == 130, err
    assert err.strip().splitlines()[-1] == "cosim: interrupted" and "Traceback" not in err, err
    assert took < PROMPT, took


def test_pages_opened_and_closed_leave_the_terminal_quiet(tmp_path, write_spec, browser):  # noqa: F811
    """Before, every page opened printed four bokeh warnings (EMPTY_LAYOUT: the room's tabs are built when first
    shown), a tab closed while the server sent to it one more, and every re-run one more; the terminal now shows
    only what the user needs: the link, and at Ctrl-C `cosim: interrupted`."""
    from cosim.analysis.room import browser as B

    folder = linear_ode_sweep(tmp_path / "decay", write_spec).parent
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "explore", str(folder)], env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    link = proc.stdout.readline().split(" is at ")[1].split()[0]
    count, _ = B.load(browser, link)
    assert count.startswith("<b>3</b> of 3 designs")
    # a re-run from the Selection tab: bokeh's server warned 'reference already known' at every click
    browser.execute_script("Bokeh.documents[0].get_model_by_name('cloud-source').selected.indices = [0];")
    B.show_tab(browser, 2)
    B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('selected').text.includes('1 design(s)');")
    B.click_widget(browser, "rerun")
    status = B.wait_for(browser, "const s = doc.get_model_by_name('rerun-status').text; "
                                 "return s.includes(' ok in ') || s.includes('failed') ? s : null;")
    assert " ok in " in status, status
    home = browser.current_window_handle
    for i in range(6):  # tabs closed while loading, just loaded, or after their first updates
        browser.switch_to.new_window("tab")
        browser.get(link)
        time.sleep(0.3 + (i % 3) * 0.8)
        browser.close()
        browser.switch_to.window(home)
    time.sleep(1.0)
    send(proc, "SIGINT")
    code, err, _ = ended(proc)
    assert code == 130 and err == "cosim: interrupted\n", err
