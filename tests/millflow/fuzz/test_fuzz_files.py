"""Issue 10 §6: random mutations of every example input, through the command line.

Each mutation (a value swapped for another type or an extreme number, a line deleted, the
file truncated, bytes inserted) must give exit 0 with a result, or exit 2 (bad input) or
1 (a failed solve) with one line on stderr naming the problem: never a traceback and
never an "internal error". The default run tries a few dozen mutations per file type;
``-m slow`` tries many more.
"""
import re
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from millflow.cli import main
from tests import paths

FLOWSHEETS = sorted(p for p in paths.FLOWSHEETS.glob("*.toml") if "aggregating" not in p.name)
TRACER = paths.DOCS / "examples" / "tracer_tis.csv"
ASSIGN = re.compile(r"^(\s*[A-Za-z_][A-Za-z0-9_.]*\s*=\s*)(.+?)(\s*(#.*)?)$")

VALUES = ["[1.0, 2.0]", '"text"', "true", "1e308", "-1e308", "0", "-1", "1e-300", "nan", "inf", "{}", "[]",
          '""', "2.7", "-0.0", "1e999"]


def mutate(text: str, kind: int, where: int, value: str, junk: bytes) -> bytes:
    lines = text.splitlines(keepends=True)
    idx = [k for k, line in enumerate(lines) if ASSIGN.match(line.rstrip("\n"))]
    if kind == 0 and idx:  # a value replaced
        k = idx[where % len(idx)]
        m = ASSIGN.match(lines[k].rstrip("\n"))
        lines[k] = f"{m.group(1)}{value}\n"
    elif kind == 1 and lines:  # a line deleted
        del lines[where % len(lines)]
    elif kind == 2:  # truncated
        data = "".join(lines).encode()
        return data[: where % max(len(data), 1)]
    else:  # bytes inserted
        data = "".join(lines).encode()
        k = where % max(len(data), 1)
        return data[:k] + junk + data[k:]
    return "".join(lines).encode()


def _check(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code in (0, 1, 2), (code, err)
    assert "Traceback" not in err and "internal error" not in err, err
    if code:
        lines = [line for line in err.splitlines() if "warning:" not in line]
        assert len(lines) == 1 and lines[0].startswith("millflow "), err


MUTATION = dict(kind=st.integers(0, 3), where=st.integers(0, 10_000), value=st.sampled_from(VALUES),
                junk=st.binary(min_size=1, max_size=6))


@pytest.mark.parametrize("source", FLOWSHEETS, ids=lambda p: p.stem)
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(**MUTATION)
def test_mutated_flowsheets(source, capsys, kind, where, value, junk):
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / source.name
        f.write_bytes(mutate(source.read_text(encoding="utf-8"), kind, where, value, junk))
        _check(["run", str(f), "--no-plots", "--quiet", "--out", str(Path(tmp) / "out")], capsys)


@settings(max_examples=30, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(**MUTATION)
def test_mutated_tracer_files(capsys, kind, where, value, junk):
    text = TRACER.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    if kind == 0:  # a number replaced: the CSV has no "key = value" lines
        k = 1 + where % (len(lines) - 1)
        lines[k] = lines[k].split(",")[0] + "," + value.strip('"') + "\n"
        data = "".join(lines).encode()
    else:
        data = mutate(text, kind, where, value, junk)
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "tracer.csv"
        f.write_bytes(data)
        _check(["fit-rtd", str(f), "--no-plots", "--quiet", "--json"], capsys)


@pytest.mark.slow
@pytest.mark.parametrize("source", FLOWSHEETS, ids=lambda p: p.stem)
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(**MUTATION)
def test_mutated_flowsheets_long(source, capsys, kind, where, value, junk):
    test_mutated_flowsheets.hypothesis.inner_test(source, capsys, kind, where, value, junk)


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(**MUTATION)
def test_mutated_fit_configs_load_or_say_why(tmp_path_factory, kind, where, value, junk):
    """The fit config loader: a mutated config loads, or raises millflow's InputError (the
    CLI's exit 2), never another exception."""
    from millflow.errors import MillflowError
    from millflow.fitting.config import load_config
    from tests.millflow.fitting.test_fit_cli import _write_batch_case

    tmp = tmp_path_factory.mktemp("cfg")
    cfg, _ = _write_batch_case(tmp)
    cfg.write_bytes(mutate(cfg.read_text(), kind, where, value, junk))
    try:
        c = load_config(cfg)
        c.model()
    except MillflowError:
        pass
