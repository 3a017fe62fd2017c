"""Build of the optional compiled kernel; everything else is in pyproject.toml.

millflow._eigenbasis holds the row recurrences of the exact breakage solver
(millflow/_eigenbasis.c, plain C on the buffer protocol, no numpy headers). It is
optional: where no C compiler is available the build goes on without it and
millflow.linalg runs the same arithmetic in numpy (slower, same results to rounding).
"""
from setuptools import Extension, setup

setup(ext_modules=[Extension("millflow._eigenbasis", ["millflow/_eigenbasis.c"], optional=True)])
