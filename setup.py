"""Build of the optional compiled kernels; everything else is in pyproject.toml.

- millflow._eigenbasis: the row recurrences of the exact breakage solver
  (millflow/_eigenbasis.c);
- millflow._cells: the class loop of a row of well-mixed cells (millflow/_cells.c).

Plain C on the buffer protocol, no numpy headers. Both are optional: where no C
compiler is available the build goes on without them and millflow runs the same
arithmetic in numpy (slower, same results to rounding; millflow.compiled).
"""
from setuptools import Extension, setup

HEADERS = ["millflow/_buffer.h"]  # shared buffer checks; listed in MANIFEST.in for the sdist

setup(ext_modules=[
    Extension("millflow._eigenbasis", ["millflow/_eigenbasis.c"], depends=HEADERS, optional=True),
    Extension("millflow._cells", ["millflow/_cells.c"], depends=HEADERS, optional=True),
])
