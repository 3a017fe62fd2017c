"""Forward models for fitting: the earlier single home of the fit's model code, kept as aliases.

The code lives by job in :mod:`millflow.fitting.spec` (what is fitted: :class:`ModelSpec`,
:class:`Parameter`, defaults), :mod:`millflow.fitting.translate` (a parameter vector into
S, b, d* and transport values, eq. 10 in one place) and :mod:`millflow.fitting.forward`
(:class:`ForwardModel`: the model compiled on a grid against a data set). The names below
are re-exported so that existing imports keep working.
"""
from millflow.fitting.forward import ForwardModel, auto_grid
from millflow.fitting.spec import (BREAKAGE_FORMS, CLASSIFICATIONS, FORWARD_TOL, MODES, RATE_FORMS, TRANSPORT_FIT,
                                   TRANSPORTS, ModelSpec, Parameter, canonical_location, default_parameters)

__all__ = ["Parameter", "ModelSpec", "ForwardModel", "RATE_FORMS", "BREAKAGE_FORMS", "MODES", "canonical_location",
           "CLASSIFICATIONS", "TRANSPORTS", "TRANSPORT_FIT", "FORWARD_TOL", "default_parameters", "auto_grid"]
