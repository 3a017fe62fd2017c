"""The package's structure: no import circles in millflow or rtd, rtd stands alone, and
imports run one way through the layers (kinetics -> mill -> flowsheet/fitting -> commands).

Imports are read from the source with ``ast`` (every import statement, also those inside
functions: a lazy import is still a dependency), so this checks the code as written, not
what one interpreter session happened to load.
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("millflow", "rtd")

# Layers, lowest first: a module may import from its own layer and the ones below.
LAYERS = [
    ("base", ("millflow.errors", "millflow._interrupt", "millflow.grid", "millflow.compiled", "millflow.plotting",
              "millflow.inputs", "millflow._lazy", "millflow.threads", "millflow.balances",
              "millflow.progress", "millflow.report", "millflow._dataset",  # report: pages from summaries, no physics
              "millflow.ode")),  # ode: the one home of solve_ivp
    ("kinetics", ("millflow.psd", "millflow.checks", "millflow.classifiers", "millflow.cyclones", "millflow.breakage",
                  "millflow.linalg",
                  "millflow.batch", "millflow.nonlinear")),  # nonlinear: where issue 12's kinetics land
    ("mill", ("millflow.mill",)),
    ("circuits", ("millflow.flowsheet", "millflow.fitting", "millflow.scaleup",
                  "millflow.sweep")),  # sweep: where issue 14's sweeps land
    ("studies", ("millflow.falsify", "millflow.synthetic", "millflow.survey")),  # synthetic: problems with known truths
    ("commands", ("millflow.bench", "millflow.commands", "millflow.cli", "millflow.__main__")),
]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


def _resolve(name: str, modules) -> str | None:
    """The longest known module that ``name`` names (a module, or a name inside one)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def import_graph() -> dict[str, set[str]]:
    modules = _modules()
    graph = {m: set() for m in modules}
    for mod, path in modules.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative: from . import x
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    stem = ".".join(base + ([node.module] if node.module else []))
                else:
                    stem = node.module or ""
                targets = [f"{stem}.{a.name}" for a in node.names]
            for t in targets:
                if t.split(".")[0] in PACKAGES:
                    hit = _resolve(t, modules)
                    if hit and hit != mod:
                        graph[mod].add(hit)
    return graph


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _layer(mod: str) -> int | None:
    for rank, (_, prefixes) in enumerate(LAYERS):
        if any(mod == p or mod.startswith(p + ".") for p in prefixes):
            return rank
    return None


def test_no_import_circles():
    graph = import_graph()
    # the package __init__ files re-export their modules; a module importing its own
    # package's __init__ would close a circle and is counted
    assert _cycles(graph) == []


def test_rtd_imports_nothing_of_millflow():
    graph = import_graph()
    leaks = {m: sorted(t for t in ts if t.startswith("millflow")) for m, ts in graph.items() if m.startswith("rtd")}
    assert {m: t for m, t in leaks.items() if t} == {}


def test_imports_run_down_the_layers():
    graph = import_graph()
    upward = []
    for mod, targets in graph.items():
        rank = _layer(mod)
        if rank is None:
            continue
        for t in targets:
            r = _layer(t)
            if r is not None and r > rank:
                upward.append(f"{mod} ({LAYERS[rank][0]}) imports {t} ({LAYERS[r][0]})")
    assert upward == []


def test_every_module_has_a_layer():
    missing = sorted(m for m in import_graph() if m.startswith("millflow.") and _layer(m) is None)
    assert missing == [], "place these modules in LAYERS (tests/test_layers.py)"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_the_graph_sees_the_package(pkg):
    graph = import_graph()
    assert any(m.startswith(pkg) for m in graph) and sum(len(v) for v in graph.values()) > 20


def _third_party_imports(folder: Path, own: str) -> set[str]:
    """Top-level names imported by the modules of ``folder`` that are neither the package
    itself nor the standard library."""
    import sys

    names = set()
    for path in folder.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                names.add(node.module.split(".")[0])
    return {n for n in names if n != own and n not in sys.stdlib_module_names}


def test_rtd_stands_alone_as_a_distribution():
    # rtd/pyproject.toml installs the folder as the package rtd (pip install ./rtd) and
    # declares every third-party package rtd imports (as a dependency or in an extra)
    import re
    import tomllib

    meta = tomllib.loads((ROOT / "rtd" / "pyproject.toml").read_text(encoding="utf-8"))
    assert meta["project"]["name"] != "rtd"  # that name on PyPI is another package
    assert meta["tool"]["setuptools"]["package-dir"] == {"rtd": "."}
    assert meta["tool"]["setuptools"]["packages"] == ["rtd"]
    declared = [*meta["project"]["dependencies"], *sum(meta["project"]["optional-dependencies"].values(), [])]
    declared = {re.split(r"[<>=!~\[ ;]", d, maxsplit=1)[0].lower() for d in declared}
    assert _third_party_imports(ROOT / "rtd", "rtd") <= declared
    # millflow's own build ships the same package, so one install of the checkout has both
    root = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "rtd*" in root["tool"]["setuptools"]["packages"]["find"]["include"]


def _suite_of_test(path: Path) -> str | None:
    """The bench suite a test file of tests/millflow/bench/ is about, by its name
    (``test_<suite>_bench.py`` or ``test_bench_<suite>.py``), else None."""
    if (ROOT / "tests" / "millflow" / "bench") not in path.parents:
        return None
    stem = path.stem
    for pre, post in (("test_", "_bench"), ("test_bench_", "")):
        if stem.startswith(pre) and stem.endswith(post) and len(stem) > len(pre) + len(post):
            return stem[len(pre): len(stem) - len(post)]
    return None


def test_tests_take_no_fixtures_from_the_benchmark_suites():
    # the bench suites are tools of the command line; synthetic problems shared with the
    # tests live in millflow.synthetic. A test may run a suite (its entry points) but take
    # nothing else from it; only the tests of a suite (tests/millflow/bench/test_<suite>_bench.py)
    # read that suite's own parts.
    entry = {"run", "format_table", "DESCRIPTION"}
    offenders = []
    for path in (ROOT / "tests").rglob("*.py"):
        own = _suite_of_test(path)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        suites = set()  # local names bound to another suite's module
        for node in ast.walk(tree):
            if isinstance(node, ast.Import) and any(a.name.startswith("millflow.bench") for a in node.names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: import of the bench package")
            elif isinstance(node, ast.ImportFrom) and node.module == "millflow.bench":
                suites |= {a.asname or a.name for a in node.names if a.name != own}
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("millflow.bench."):
                if node.module == f"millflow.bench.{own}":
                    continue
                taken = {a.name for a in node.names} - entry
                if taken:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {sorted(taken)}")
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in suites
                    and node.attr not in entry):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr}")
    assert offenders == []


def test_the_rule_above_names_each_suites_tests():
    bench = ROOT / "tests" / "millflow" / "bench"
    assert _suite_of_test(bench / "test_flowsheet_bench.py") == "flowsheet"
    assert _suite_of_test(bench / "test_bench_core.py") == "core"
    assert _suite_of_test(bench / "test_bench_plot.py") == "plot"  # no such suite: nothing of one is its own
    assert _suite_of_test(ROOT / "tests" / "millflow" / "flowsheet" / "test_flowsheet_bench.py") is None


# ------------------------------------------------------------------ one transport dispatch
# "A transport is dispatched in one place" (docs/CONTRACTS.md): millflow.mill.transport
# says what a transport is (its kind, its cells, its axis, what a fit can estimate) and
# solves it; code outside millflow/mill/ asks it instead of comparing transport names or
# testing rtd classes. Names as *values* (a default, a user's file being written, a label)
# are not dispatch and are not looked at.
def _transport_words() -> set[str]:
    from rtd import names

    # "cells" is also a place of classification (where = "cells"): not a word of its own here
    return ({*names.TRANSPORTS, *names.ALIASES} - {"cells"}) | {"well_mixed"}


def _rtd_classes() -> set[str]:
    import rtd

    return {n for n in rtd.__all__ if n[:1].isupper() and isinstance(getattr(rtd, n), type)}


#: Sites left outside millflow/mill/, as "path: source of the node" (an assignment: its
#: target) -> why it is not a transport dispatch. A new entry needs its reason.
TRANSPORT_DISPATCH_ALLOWED: dict[str, str] = {
    # the valid values of a falsification config's truth.type (a user's file); the three
    # RTD truths among them are told apart by millflow.falsify.truths.is_rtd_truth, which
    # asks millflow.mill.transport
    "millflow/falsify/config.py: TRUTH_TYPES = ...": "the truth types a study config may name",
    # the valid values of a fit config's mode; the modes that name a transport (plug_flow,
    # well_mixed) are resolved by millflow.mill.transport.mode_transport
    "millflow/fitting/spec.py: MODES = ...": "the fit's modes a fit config may name",
}


def _dispatch_nodes(tree, words: set[str], classes: set[str]) -> list[tuple[int, str]]:
    """(line, source) of the transport dispatches in a module: comparisons with transport
    names, dicts keyed by them, named tuples of them (``x in _AXIAL_TRANSPORTS``) and
    isinstance tests on rtd classes, also comparisons with the fit's ``mode`` (its words
    ``plug_flow`` and ``well_mixed`` name a transport, resolved by
    ``millflow.mill.transport.mode_transport``); an assignment is given by its target."""

    def named(node) -> bool:
        if isinstance(node, ast.Constant):
            return isinstance(node.value, str) and node.value in words
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return any(named(e) for e in node.elts)
        return False

    def rtd_class(node) -> bool:
        if isinstance(node, ast.Tuple):
            return any(rtd_class(e) for e in node.elts)
        if isinstance(node, ast.Attribute):
            return isinstance(node.value, ast.Name) and node.value.id == "rtd"
        return isinstance(node, ast.Name) and node.id in classes

    out = []
    for node in ast.walk(tree):
        hit, text = False, None
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            hit = any(named(o) for o in operands)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, (ast.Tuple, ast.List, ast.Set)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            hit = any(named(e) for e in node.value.elts if isinstance(e, ast.Constant)) and not any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in targets)  # __all__: function names
            text = f"{ast.unparse(targets[0])} = ..."
        elif isinstance(node, ast.Dict):
            hit = any(k is not None and named(k) for k in node.keys)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in (
                "isinstance", "issubclass") and len(node.args) == 2:
            hit = rtd_class(node.args[1])
        if hit:
            out.append((node.lineno, text or ast.unparse(node)))
    return out


def transport_dispatch_sites() -> list[str]:
    """The transport dispatches of millflow outside millflow/mill/ not allowed below."""
    words, classes = _transport_words(), _rtd_classes()
    sites = []
    mill = ROOT / "millflow" / "mill"
    for path in sorted((ROOT / "millflow").rglob("*.py")):
        if mill in path.parents:
            continue
        rel = path.relative_to(ROOT).as_posix()
        for line, text in _dispatch_nodes(ast.parse(path.read_text(encoding="utf-8")), words, classes):
            if f"{rel}: {text}" not in TRANSPORT_DISPATCH_ALLOWED:
                sites.append(f"{rel}:{line}: {text}")
    return sites


def test_transports_are_dispatched_in_the_mill_layer():
    assert transport_dispatch_sites() == [], "ask millflow.mill.transport instead (or allow the site, with why)"


def test_the_dispatch_rule_sees_a_dispatch():
    src = """
if spec.transport == "plug_flow" or isinstance(m, rtd.TanksInSeries) or x in ("tis", "other"):
    key = {"axial_dispersion": "pe"}.get(t)
_AXIAL = ("plug_flow", "axial_dispersion")
if spec.mode == "plug_flow" or cfg.get("mode") in ("well_mixed", "plug_flow") or where == "cells":
    table = {"model": "tanks_in_series", "n": 3}
__all__ = ["well_mixed", "tanks_in_series"]
cases = [("plug_flow", 1.0)]
"""
    found = [text for _, text in _dispatch_nodes(ast.parse(src), _transport_words(), _rtd_classes())]
    assert sorted(found) == sorted([
        "spec.transport == 'plug_flow'", "isinstance(m, rtd.TanksInSeries)", "x in ('tis', 'other')",
        "{'axial_dispersion': 'pe'}", "_AXIAL = ...", "spec.mode == 'plug_flow'",
        "cfg.get('mode') in ('well_mixed', 'plug_flow')"])
