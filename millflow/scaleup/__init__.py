"""Scale-up from a lab fit to a plant mill, with the fit's uncertainty carried along.

Plain functions (power, scaling, hold-up) in :mod:`.power` and :mod:`.scaling`;
:mod:`.fitted` reads a ``millflow fit --json`` result (its vector decoded by the fit's
translator); :mod:`.plant` describes mills by dimensions and the circuit they work in;
:mod:`.study` makes the plant a flowsheet and solves it with :mod:`millflow.flowsheet`
(scale-up holds no solver of its own); :mod:`.predict` binds them; :mod:`.uncertainty`
propagates eq. 9's covariance; :mod:`.modelform` states the model-form and grid parts of
the band; :mod:`.api` returns the result object.
"""
from millflow._lazy import attach

# Served on first use: a flowsheet reading a mill by its dimensions needs the plant
# module, not the fitting and uncertainty machinery (scipy.stats).
__getattr__, __dir__ = attach(__name__, {
    "millflow.scaleup.api": ("ScaleupResult", "predict_plant"),
    "millflow.scaleup.fitted": ("FittedBreakage", "FittedDistribution", "FittedRate", "fit_from_dict", "load_fit"),
    "millflow.scaleup.plant": ("Circuit", "MillDesign"),
    "millflow.scaleup.power": ("austin_power", "ball_charge_mass", "bond_rowland_power", "charge_arm",
                               "critical_speed", "gross_power", "hogg_fuerstenau_power", "mill_power"),
    "millflow.scaleup.predict": ("ScaleUp",),
    "millflow.scaleup.scaling": ("austin_factors", "herbst_fuerstenau_rates", "specific_rates"),
    "millflow.scaleup.study": ("PlantStudy",),
    "millflow.scaleup.uncertainty": ("delta_method", "monte_carlo"),
})

__all__ = ["Circuit", "FittedBreakage", "FittedDistribution", "FittedRate", "MillDesign", "PlantStudy", "ScaleUp",
           "ScaleupResult", "austin_factors",
           "austin_power", "ball_charge_mass", "bond_rowland_power", "charge_arm", "critical_speed",
           "delta_method", "fit_from_dict", "gross_power", "herbst_fuerstenau_rates", "hogg_fuerstenau_power",
           "load_fit",
           "mill_power", "monte_carlo", "predict_plant", "specific_rates"]
