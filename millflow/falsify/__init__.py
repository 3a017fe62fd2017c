"""Falsification studies: how wrong fitted kinetics are when the assumed model misses physics.

Falsification studies (Principle I): fit an assumed linear model to synthetic
data from a truth with model error, over replicates and strengths, and measure bias,
coverage, goodness of fit, residual structure and rate drift. See docs/model-error.md.

Nothing in millflow imports this package except the ``millflow falsify`` command and its
benchmark.
"""
from millflow.falsify.design import Design, batch_design, continuous_design
from millflow.falsify.noise import AR1Noise, GaussianNoise
from millflow.falsify.nonlinear_truths import AggregationTruth, PopulationTruth
from millflow.falsify.study import StudyResult, lag1, runs_test, study
from millflow.falsify.truths import (BREAKAGE_TRUTH, CallableTruth, LinearTruth, SlowingDownTruth, Truth,
                                     classification_truth, rtd_truth)

__all__ = ["Design", "batch_design", "continuous_design", "GaussianNoise", "AR1Noise", "study", "StudyResult",
           "runs_test", "lag1", "Truth", "LinearTruth", "SlowingDownTruth", "CallableTruth", "rtd_truth",
           "classification_truth", "BREAKAGE_TRUTH", "AggregationTruth", "PopulationTruth"]
