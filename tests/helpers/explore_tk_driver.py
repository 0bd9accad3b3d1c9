"""``cosim explore --tk ...`` as the command runs it, with the clicks of a user made by Tk timers in the process.

tests/analysis/test_explore_signals.py starts this as a real process and signals it.  The first design is selected and
re-run (as the 'Re-run selected' button does when clicked) once the window is up.  ``ready`` on stdout says
when to signal: with ``--when animating``, one second after the re-run's arm animation started; with
``--when rerun``, just before the re-run starts (the signal then lands while it runs).
"""

import sys

from cosim.analysis import explorer

WHEN = sys.argv.pop(1).removeprefix("--when=")
opened = explorer.ExplorerWindow.__init__


def open_and_rerun(self, root, state):
    opened(self, root, state)
    state.select(0)

    def say_ready():
        print("ready", flush=True)

    def rerun():
        if WHEN == "rerun":
            say_ready()
            root.after(300, self.rerun_button.invoke)
        else:
            self.rerun_button.invoke()

    def animating():
        if self.trace_windows and self.trace_windows[0].animation is not None:
            root.after(1000, say_ready)
        else:
            root.after(100, animating)

    root.after(300, rerun)
    if WHEN == "animating":
        root.after(100, animating)


explorer.ExplorerWindow.__init__ = open_and_rerun

from cosim.cli.main import main  # noqa: E402

sys.exit(main())
