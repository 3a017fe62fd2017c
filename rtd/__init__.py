"""rtd: residence time distributions, compartment networks and tracer-data fitting.

Standalone: imports nothing from millflow. Times are in any unit used consistently
(tau and t in the same unit). Every model gives ``pdf`` (E), ``cdf`` (F), ``laplace``
(E_hat, real or complex s), ``mean``, ``variance``, ``params`` and
``analytic_for_re_s_greater_than``.

>>> import rtd
>>> rtd.TanksInSeries(tau=2.0, n=3).variance
1.3333333333333333
>>> round(float(rtd.Series(*[rtd.PerfectMixing(1.0)] * 3).laplace(0.5)), 12)
0.296296296296
"""
from rtd.axial import AxialDispersion
from rtd.compartments import CompartmentNetwork, RecirculatingCells
from rtd.compose import Parallel, Series, talbot_inverse
from rtd.fit import MODELS, FitResult, compare, fit
from rtd.models import ParameterError, PerfectMixing, PlugFlow, RTDError, RTDModel, TanksInSeries
from rtd.names import TRANSPORTS, canonical_name
from rtd.names import build as build_transport
from rtd.tracer import (Moments, TracerCurve, TracerError, check_tracer, convolve_inlet, moments,
                        normalise, read_tracer_csv, step_moments, subtract_baseline)

__all__ = [
    "AxialDispersion", "CompartmentNetwork", "FitResult", "MODELS", "Moments", "Parallel",
    "ParameterError", "PerfectMixing", "PlugFlow", "RTDError", "RTDModel", "RecirculatingCells",
    "Series", "TanksInSeries", "TracerCurve", "TracerError", "check_tracer", "compare",
    "convolve_inlet", "fit", "moments", "normalise", "read_tracer_csv", "step_moments",
    "subtract_baseline", "talbot_inverse", "TRANSPORTS", "canonical_name", "build_transport",
]
