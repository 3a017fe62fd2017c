"""The `millflow` command line.

Each sub-command lives in its own module of :mod:`millflow.commands` and exposes
``add_parser(subparsers)``, which registers the sub-command and sets ``func`` (a
callable taking the parsed arguments and returning an exit code).
:data:`millflow.commands.COMMANDS` maps the names to the modules: a command line
imports the module of the command it runs and no other (the rest are listed by name
and help line only), so that ``millflow run`` does not pay for what ``fit-rtd`` or
``scaleup`` import.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import re
import signal
import sys
import threading
import warnings

from millflow.errors import MillflowError, OutputError, SolverError


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The command-line parser. With ``argv``, only the sub-command it names is built in
    full (its module imported); the others are listed with their help line. Without
    ``argv`` (documentation, tests), every sub-command is built."""
    from millflow import __version__
    from millflow.commands import COMMANDS

    parser = argparse.ArgumentParser(
        prog="millflow",
        description="Population-balance simulation of grinding mills and circuits.",
        epilog="example: millflow run flowsheets/closed_circuit_ball_mill.toml",
    )
    parser.add_argument("--version", action="version", version=f"millflow {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    wanted = set(COMMANDS) if argv is None else {_command_of(argv)}
    for name, (module, help_line) in sorted(COMMANDS.items()):
        if name in wanted:
            importlib.import_module(f"millflow.commands.{module}").add_parser(sub)
        else:  # listed under --help and in "invalid choice" messages; never parsed
            sub.add_parser(name, help=help_line, add_help=False)
    for name, p in sub.choices.items():  # help text is plain text: no reStructuredText roles
        p.description = _plain(p.description)
        p.epilog = p.epilog or f"example: {EXAMPLES.get(name, f'millflow {name} --help')}"
        p.formatter_class = argparse.RawDescriptionHelpFormatter
    return parser


def _command_of(argv: list[str]) -> str | None:
    """The sub-command an argument list names: its first word that is not an option
    (the top level takes no option with a value)."""
    return next((a for a in argv if not a.startswith("-")), None)


#: One example line per command (shown under --help).
EXAMPLES = {
    "run": "millflow run flowsheets/closed_circuit_ball_mill.toml --out results",
    "fit": "millflow fit examples/knife_mill/knife_mill.toml --json",
    "fit-rtd": "millflow fit-rtd docs/examples/tracer_tis.csv --model tis --out tis-fit",
    "scaleup": "millflow scaleup lab_fit.json --to examples/scaleup/plant.toml --target-p80-um 150",
    "falsify": "millflow falsify docs/examples/falsify/tanks.toml --out study",
    "bench": "millflow bench core --quick",
    "balance": "millflow balance examples/survey/survey.toml --out survey-balance",
}


def _plain(text: str | None) -> str | None:
    """Docstring text without reStructuredText markup (``x``, :func:`x`, :mod:`~a.b`)."""
    if not text:
        return text
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "")


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that result folders are cleaned up."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings on the command line as one line each, without source locations."""
    print(f"millflow: warning: {category.__name__}: {message}", file=sys.stderr if file is None else file)


def main(argv: list[str] | None = None) -> int:
    """Run one command; return its exit status.

    0 success; 1 a failed solve (SolverError), results that could not be written
    (OutputError), SIGTERM or an internal error; 2 bad input (any other MillflowError,
    and argparse's usage errors); 130 SIGINT. Every failure is one line on stderr;
    MILLFLOW_DEBUG=1 adds the traceback of an internal error.
    """
    whole_process = argv is None  # the command line itself: the process exits after the command
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--version"]:  # answered before the sub-commands (and numpy) are imported
        from millflow import __version__

        print(f"millflow {__version__}")
        raise SystemExit(0)  # as argparse's version action does
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    name = f"millflow {args.command}"
    if whole_process:
        _hide_dask(args.command)
    previous = signal.getsignal(signal.SIGTERM) if _main_thread() else None
    previous_int = signal.getsignal(signal.SIGINT) if _main_thread() else None
    if previous is not None:
        signal.signal(signal.SIGTERM, _on_sigterm)
    if previous_int is not None:  # Ctrl-C raises KeyboardInterrupt (cleaned up below) while the command runs
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            return int(args.func(args) or 0)
    except (SolverError, OutputError) as err:
        print(f"{name}: error: {one_line(err)}", file=sys.stderr)
        return 1
    except MillflowError as err:
        print(f"{name}: error: {one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted; no partial results were written", file=sys.stderr)
        return 130
    except Terminated:
        print(f"{name}: terminated (SIGTERM); no partial results were written", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into a command that stopped reading (e.g. head)
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # silence the flush at exit
        return 0
    except Exception as err:  # a bug: one line, not a traceback (MILLFLOW_DEBUG=1 shows it)
        if os.environ.get("MILLFLOW_DEBUG"):
            raise
        print(f"{name}: internal error: {type(err).__name__}: {one_line(err)} "
              "(please report it; MILLFLOW_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)


def _hide_dask(command: str) -> None:
    """In a whole ``millflow`` process (the command line, not a call of :func:`main` from
    Python) of a command that holds no dask array, make ``import dask`` fail, so that
    xarray's duck-array checks find dask absent instead of importing dask.array (0.5-1 s
    of a small run's start-up). ``sys.modules[name] = None`` is Python's documented way
    to block an import; it lasts until the process exits, right after the command."""
    from millflow.commands import USES_DASK

    if command not in USES_DASK and "dask" not in sys.modules:
        sys.modules["dask"] = None


def one_line(err) -> str:
    """An error message as one line a person reads: numpy reprs as plain numbers
    (np.float64(0.5) -> 0.5), a doubled sign (--1e+07) single, a prefix repeated by
    nested wrappers ("a.toml: a.toml: ...") once, whitespace collapsed."""
    msg = " ".join(str(err).split())
    msg = re.sub(r"np\.(?:float|int|uint|bool_)\w*\(([^()]*)\)", r"\1", msg)
    msg = re.sub(r"(?<![\w-])--(?=\d)", "-", msg)
    msg = re.sub(r"^((?:[^:]+: ))\1+", r"\1", msg)
    return msg


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":
    sys.exit(main())
