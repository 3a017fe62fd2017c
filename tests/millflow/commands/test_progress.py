"""Progress, one rule for every command (millflow.progress): on a terminal each command
that can run longer than 2 s shows what it is doing on stderr; ``--quiet`` hides that and
nothing else (the results still print); with stderr not a terminal (a log, a pipe) there
is no progress at all. Each command runs in a child process whose stderr is a
pseudo-terminal."""
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import time

import pytest

from tests import paths
from tests.millflow.commands.test_file_conventions import FALSIFY  # the same small study

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
if sys.platform != "win32":
    import fcntl
    import termios

FS, EX = paths.FLOWSHEETS, paths.EXAMPLES


def _small_fit_config(folder):
    """examples/scaleup/lab_fit.toml with one local start: a fit of about a second."""
    text = (EX / "scaleup" / "lab_fit.toml").read_text()
    text = text.replace('"lab_psd.csv"', f'"{EX / "scaleup" / "lab_psd.csv"}"')
    text = text.replace('"lab_process.csv"', f'"{EX / "scaleup" / "lab_process.csv"}"')
    text = text.split("[optimizer]")[0] + "[optimizer]\nglobal = false\nstarts = 1\nmaxiter = 20\n"
    (folder / "small.toml").write_text(text)
    return folder / "small.toml"


def run_on_terminal(argv, cwd, *, stderr_tty=True, until=None, timeout=300):
    """(exit code, stdout, stderr) of ``python -m millflow argv`` with stderr on a
    pseudo-terminal (or a pipe); with ``until``, interrupted (SIGINT) once stderr holds
    every string of it."""
    env = dict(os.environ, COLUMNS="120", LINES="40", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1", TERM="xterm")
    if stderr_tty:
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))  # a terminal 120 wide
        err_fd = slave
    else:
        master, err_fd = None, subprocess.PIPE
    proc = subprocess.Popen([sys.executable, "-m", "millflow", *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=err_fd)
    if stderr_tty:
        os.close(slave)
    fds = {proc.stdout.fileno(): b""}
    fds[master if stderr_tty else proc.stderr.fileno()] = b""
    err_key = master if stderr_tty else proc.stderr.fileno()
    t0, interrupted = time.monotonic(), False
    open_fds = set(fds)
    while open_fds and time.monotonic() - t0 < timeout:
        ready, _, _ = select.select(list(open_fds), [], [], 0.5)
        for fd in ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:  # the pty's other end closed
                chunk = b""
            if not chunk:
                open_fds.discard(fd)
            fds[fd] += chunk
        if until and not interrupted and all(u.encode() in fds[err_key] for u in until):
            proc.send_signal(signal.SIGINT)
            interrupted = True
        if proc.poll() is not None and not ready:
            break
    if proc.poll() is None:
        proc.kill()
    code = proc.wait(timeout=30)
    if stderr_tty:
        os.close(master)
    return code, fds[proc.stdout.fileno()].decode(errors="replace"), fds[err_key].decode(errors="replace")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("progress-inputs")
    (d / "tanks.toml").write_text(FALSIFY)
    small = _small_fit_config(d)
    code, out, err = run_on_terminal(["fit", str(small), "--json", "--quiet", "--out", str(d / "fit")], d,
                                     stderr_tty=False)
    assert code == 0, err
    (d / "fit.json").write_text(out.splitlines()[0])
    return d


#: command -> (arguments, what its progress shows, what its results print on stdout)
COMMANDS = {
    "run": (["run", f"{FS}/closed_circuit_ball_mill.toml", "--no-plots"], "millflow run", "P80 um"),
    "compare": (["compare", f"{FS}/open_circuit_ball_mill.toml", f"{FS}/closed_circuit_ball_mill.toml",
                 "--no-plots"], "millflow compare", "circulating load"),
    "sweep": (["sweep", f"{FS}/closed_circuit_ball_mill.toml", "--vary", "units.ball_mill.power_kW=3000:4600:3",
               "--scheduler", "serial", "--no-plots"], "sweep", "3 cases"),
    "balance": (["balance", f"{EX}/survey/survey.toml", "--no-fit", "--no-plots"], "millflow balance",
                "chi-square"),
    "fit-rtd": (["fit-rtd", f"{paths.DOCS}/examples/tracer_tis.csv", "--model", "tis", "--model", "cells",
                 "--no-plots"], "millflow fit-rtd", "moments"),
    "fit": (["fit", "{inputs}/small.toml", "--no-plots"], "millflow fit", "SER"),
    "scaleup": (["scaleup", "{inputs}/fit.json", "--to", f"{EX}/scaleup/plant.toml", "--band-method", "delta",
                 "--no-plots"], "millflow scaleup", "P80"),
    "falsify": (["falsify", "{inputs}/tanks.toml", "--no-plots"], "millflow falsify", "coverage"),
}


@pytest.mark.parametrize("quiet", [False, True], ids=["progress", "quiet"])
@pytest.mark.parametrize("command", list(COMMANDS))
def test_progress_on_a_terminal_and_quiet_hides_only_it(command, quiet, inputs, tmp_path):
    argv, shows, result = COMMANDS[command]
    argv = [a.replace("{inputs}", str(inputs)) for a in argv] + ["--out", str(tmp_path / "o")]
    code, out, err = run_on_terminal(argv + (["--quiet"] if quiet else []), tmp_path)
    assert code == 0, err[-2000:]
    assert result in out  # the results print either way
    if quiet:
        assert shows not in err and "\r" not in err  # no bar, no progress line
    else:
        assert shows in err and "\r" in err, err[-2000:]  # a bar rewritten in place


@pytest.mark.parametrize("command", ["run", "fit-rtd", "falsify"])
def test_no_progress_when_stderr_is_not_a_terminal(command, inputs, tmp_path):
    argv, shows, result = COMMANDS[command]
    argv = [a.replace("{inputs}", str(inputs)) for a in argv] + ["--out", str(tmp_path / "o")]
    code, out, err = run_on_terminal(argv, tmp_path, stderr_tty=False)
    assert code == 0 and result in out
    assert shows not in err and "\r" not in err


@pytest.mark.parametrize("argv,seen", [
    # long commands: their progress shows while they run (then they are interrupted)
    (["bench", "core"], ["millflow bench", "work precision: ", "N = "]),
    (["diagnose", "{inputs}/small.toml", "--no-plots"], ["millflow diagnose", "fitting "]),
])
def test_long_commands_say_what_they_do(argv, seen, inputs, tmp_path):
    argv = [a.replace("{inputs}", str(inputs)) for a in argv] + ([] if argv[0] == "bench" else
                                                                ["--out", str(tmp_path / "o")])
    code, out, err = run_on_terminal(argv, tmp_path, until=seen, timeout=240)
    assert all(s in err for s in seen), err[-2000:]
    assert code == 130  # interrupted once seen: nothing written
    assert not (tmp_path / "o").exists()
