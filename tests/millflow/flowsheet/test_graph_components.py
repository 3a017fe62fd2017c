"""The unit graph's strongly connected components (recycle loops) against scipy's."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millflow.flowsheet.graph import Flowsheet


class _Node:
    def __init__(self, units, edges):
        self.units, self.streams = units, edges


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 9).flatmap(lambda n: st.tuples(st.just(n), st.lists(st.tuples(st.integers(0, n - 1),
                                                                                      st.integers(0, n - 1)),
                                                                            max_size=25))))
def test_components_partition_equals_scipy(case):
    # Flowsheet.components on any directed graph (self loops and parallel edges included)
    # gives scipy's strongly connected partition; labels may be numbered otherwise
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n, edges = case
    names = [f"u{k}" for k in range(n)]
    streams = {f"s{k}": type("S", (), {"source": names[a], "target": names[b]})() for k, (a, b) in enumerate(edges)}
    fake = _Node(dict.fromkeys(names), streams)
    labels = Flowsheet.components(fake)
    g = csr_matrix((np.ones(len(edges)), ([a for a, _ in edges], [b for _, b in edges])), shape=(n, n))
    ref = connected_components(g, directed=True, connection="strong")[1]
    assert labels.shape == (n,)
    assert np.array_equal(labels[:, None] == labels[None, :], ref[:, None] == ref[None, :])


def test_import_flowsheet_needs_no_sparse_or_interpolate():
    from millflow._lazy import heavy_modules_loaded  # noqa: F401
    import json
    import subprocess
    import sys

    from millflow._lazy import import_path_env

    code = ("import sys, json\nimport millflow.flowsheet\n"
            "print(json.dumps([m for m in ('scipy.sparse', 'scipy.interpolate') if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], env=import_path_env(), capture_output=True, text=True,
                         check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


if __name__ == "__main__":
    pytest.main([__file__])
