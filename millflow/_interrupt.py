"""Ctrl-C while the command line imports the package (see :func:`quiet_interrupt_while_importing`)."""


def quiet_interrupt_while_importing() -> None:
    """The command line (``millflow ...``, ``python -m millflow ...``) imports this package
    for seconds before its own handlers run; a Ctrl-C then ends the process without a
    traceback (SIG_DFL). :func:`millflow.cli.main` turns KeyboardInterrupt back on for the
    command itself (results folders are cleaned up) and restores this afterwards."""
    import os
    import sys

    import _signal  # the C module: no import time (``signal`` loads enum), so the window stays microseconds

    argv = list(getattr(sys, "orig_argv", []))
    as_module = "-m" in argv[:-1] and argv[argv.index("-m") + 1] == "millflow"
    as_script = len(argv) > 1 and os.path.basename(argv[1]) in ("millflow", "millflow.exe")
    if as_module or as_script:
        try:
            _signal.signal(_signal.SIGINT, _signal.SIG_DFL)
        except ValueError:  # not the main thread: signals are not ours to set
            pass

quiet_interrupt_while_importing()
