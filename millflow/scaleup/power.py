"""Tumbling-mill power and charge geometry from dimensions and operation.

Plain functions, SI inside except where the source's empirical constants fix the units
(stated per function). Net power is the power at the mill shell / pinion that the
correlation predicts; gross (motor input) power is net / drive efficiency, which the
caller supplies (no default: it is a property of the drive, not of the mill).

Models
------
- :func:`critical_speed` (exact, centrifuging of a ball at the shell).
- :func:`bond_rowland_power` (Bond 1961, as restated in metric units by Rowland 1972/1982):
  kW per tonne of balls for wet overflow ball mills.
- :func:`austin_power` (Austin, Klimpel & Luckie 1984, ch. 10, ball mills):
  m_p = 7.33 J phi_c (1 - 0.937 J) (1 - 0.1 / 2^(9 - 10 phi_c)) rho_b L D^2.3.
- :func:`hogg_fuerstenau_power` (Hogg & Fuerstenau 1972): torque-arm model,
  P = 2 pi N M_c g d_c sin(alpha), the charge a circular segment tilted by the dynamic
  angle of repose alpha, d_c the distance of its centre of mass from the mill axis.
"""
from __future__ import annotations

import math


from millflow.errors import InputError

__all__ = ["critical_speed", "check_operation", "ball_charge_mass", "bond_rowland_power", "austin_power",
           "hogg_fuerstenau_power", "charge_arm", "gross_power", "BOND_METRIC_CONSTANT"]

G = 9.80665  # standard gravity [m/s^2]

#: Bond's constant for kW per metric tonne of balls with D in metres (Rowland's metric
#: restatement of Bond's 3.1 kW per short ton with D in feet).
BOND_METRIC_CONSTANT = 4.879


def _positive(value, name):
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} = {v!r}: expected a finite number > 0")
    return v


def check_operation(critical_speed_fraction=None, ball_filling=None, powder_filling=None, where="mill"):
    """Validate the operating fractions of a ball mill.

    Validate the operating fractions: 0 < phi_c < 1, 0 < J < 0.5 (balls above the axis
    no longer form a cascading charge; every correlation here is fitted for J <= 0.45),
    0 <= U <= 2 (U = powder volume / ball-bed voids; above ~1.5 the mill is overfilled).
    """
    if critical_speed_fraction is not None:
        v = float(critical_speed_fraction)
        if not (0 < v < 1):
            raise InputError(f"{where}.critical_speed_fraction = {v!r}: expected 0 < fraction < 1 "
                             "(1 is centrifuging)")
    if ball_filling is not None:
        v = float(ball_filling)
        if not (0 < v < 0.5):
            raise InputError(f"{where}.ball_filling = {v!r}: expected 0 < J < 0.5 (fraction of mill volume "
                             "filled by the ball bed, voids included)")
    if powder_filling is not None:
        v = float(powder_filling)
        if not (0 <= v <= 2):
            raise InputError(f"{where}.powder_filling = {v!r}: expected 0 <= U <= 2 (powder volume / "
                             "ball-bed void volume)")


def critical_speed(diameter_m, ball_size_m=0.0):
    """Critical speed N_c [rev/s] of a ball mill.

    Critical speed N_c [rev/s] = sqrt(2 g / (D - d)) / (2 pi): the speed at which a ball
    of diameter d [m] at the shell of a mill of diameter D [m] (inside liners) centrifuges.
    In rpm with g = 9.81 this is the familiar 42.3 / sqrt(D - d).
    """
    D = _positive(diameter_m, "diameter_m")
    d = float(ball_size_m)
    if not (0 <= d < D):
        raise InputError(f"ball_size_m = {d!r}: expected 0 <= d < D = {D!r}")
    return math.sqrt(2 * G / (D - d)) / (2 * math.pi)


def ball_charge_mass(diameter_m, length_m, ball_filling, ball_density_kg_m3=7800.0, bed_porosity=0.4):
    """Mass of the ball charge [kg].

    Mass of balls [kg] = J V rho_b (1 - eps): V = pi D^2 L / 4 [m^3] inside liners, J the
    fraction of the mill volume filled by the ball bed, eps its porosity (0.4 for a
    random bed of balls: Austin, Klimpel & Luckie 1984).
    """
    D, L = _positive(diameter_m, "diameter_m"), _positive(length_m, "length_m")
    check_operation(ball_filling=ball_filling)
    eps = float(bed_porosity)
    if not (0 < eps < 1):
        raise InputError(f"bed_porosity = {eps!r}: expected 0 < eps < 1")
    rho_b = _positive(ball_density_kg_m3, "ball_density_kg_m3")
    return math.pi * D * D * L / 4 * float(ball_filling) * rho_b * (1 - eps)


def bond_rowland_power(diameter_m, length_m, ball_filling, critical_speed_fraction, ball_size_mm,
                       ball_density_kg_m3=7800.0, bed_porosity=0.4):
    """Bond's ball-mill power at the pinion, in Rowland's metric form.

    kW_b = 4.879 D^0.3 (3.2 - 3 V_p) phi_c (1 - 0.1 / 2^(9 - 10 phi_c)) + S_s   [kW per t balls]
    S_s = 1.102 (B - 12.5 D) / 50.8   for D > 3.3 m (ball-size factor), else 0

    D [m] inside liners, V_p = J the fraction of mill volume loaded with balls, phi_c the
    fraction of critical speed, B the ball size [mm].

    Validity: wet overflow-discharge ball mills (Rowland: multiply by 1.16 for wet
    grate discharge, 1.08 for dry), 0.35 <= J <= 0.5 as fitted by Bond, phi_c 0.6-0.8.

    Parameters
    ----------
    diameter_m, length_m : float
        Mill diameter D and length L inside liners [m].
    ball_filling : float
        Fraction J of the mill volume filled by the ball bed (voids included) [-], 0 < J < 0.5.
    critical_speed_fraction : float
        Fraction phi_c of the critical speed [-], 0 < phi_c < 1.
    ball_size_mm : float
        Ball size B [mm] (the ball-size factor of mills above 3.3 m).
    ball_density_kg_m3 : float
        Density of the balls [kg/m3] (7800 for steel).
    bed_porosity : float
        Porosity of the ball bed [-] (0.4 for a random bed).

    Returns
    -------
    dict
        ``kw_per_t_balls`` [kW/t], ``ball_mass_t`` [t], ``net_kW`` [kW].

    Raises
    ------
    InputError
        Dimensions not > 0, or operating fractions outside their range
        (:func:`check_operation`).

    References
    ----------
    F. C. Bond, Crushing and grinding calculations, Br. Chem. Eng. 6 (1961);
    C. A. Rowland, in Design and Installation of Comminution Circuits (SME, 1982), ch. 23.

    Examples
    --------
    >>> r = bond_rowland_power(4.0, 6.0, 0.35, 0.75, ball_size_mm=50.0)
    >>> round(r["net_kW"]), round(r["ball_mass_t"], 1)
    (1421, 123.5)
    """
    D = _positive(diameter_m, "diameter_m")
    check_operation(critical_speed_fraction, ball_filling)
    B = _positive(ball_size_mm, "ball_size_mm")
    J, phi = float(ball_filling), float(critical_speed_fraction)
    kwb = BOND_METRIC_CONSTANT * D ** 0.3 * (3.2 - 3 * J) * phi * (1 - 0.1 / 2 ** (9 - 10 * phi))
    if D > 3.3:
        kwb += 1.102 * (B - 12.5 * D) / 50.8
    mass_t = ball_charge_mass(D, length_m, J, ball_density_kg_m3, bed_porosity) / 1000.0
    return {"kw_per_t_balls": kwb, "ball_mass_t": mass_t, "net_kW": kwb * mass_t}


def austin_power(diameter_m, length_m, ball_filling, critical_speed_fraction, ball_density_t_m3=7.8,
                 K=7.33, A=0.937, bed_porosity=0.4):
    """Austin's ball-mill power equation (net) [kW].

    The net power is::

        m_p = K J phi_c (1 - A J) (1 - 0.1 / 2^(9 - 10 phi_c)) rho_b L D^2.3 [(1 - eps) / 0.6]

    D, L [m] inside liners, rho_b [t/m^3] the density of the balls (7.8 for steel), J the
    ball filling (bed, voids included), phi_c the fraction of critical speed; K = 7.33,
    A = 0.937 for wet overflow ball mills. K holds the standard bed porosity eps = 0.4;
    another porosity scales the charge mass, hence the power, by (1 - eps) / 0.6.

    This is Bond's power per tonne of balls (:func:`bond_rowland_power`, without the
    ball-size term) times the ball mass pi/4 D^2 L J 0.6 rho_b, rewritten per mill:
    4.879 x 3.2 x pi/4 x 0.6 = 7.36 ~ K and 3/3.2 = 0.9375 ~ A, so the two agree to 0.4 %
    (tested). The SAG-mill equation of Austin (1990) has K = 10.6 and D^2.5 with other
    charge terms; it is not this one.

    Validity: ball mills, J <= 0.45, phi_c 0.5-0.9.

    Parameters
    ----------
    diameter_m, length_m : float
        Mill diameter D and length L inside liners [m].
    ball_filling : float
        Fraction J of the mill volume filled by the ball bed (voids included) [-], 0 < J < 0.5.
    critical_speed_fraction : float
        Fraction phi_c of the critical speed [-], 0 < phi_c < 1.
    ball_density_t_m3 : float
        Density of the balls rho_b [t/m3] (7.8 for steel).
    K, A : float
        Constants of the equation (7.33 and 0.937 for wet overflow ball mills).
    bed_porosity : float
        Porosity eps of the ball bed [-] (0.4 for a random bed).

    Returns
    -------
    dict
        ``net_kW`` [kW], ``ball_mass_t`` [t], ``kw_per_t_balls`` [kW/t].

    Raises
    ------
    InputError
        Dimensions not > 0, a porosity outside (0, 1), or operating fractions outside
        their range (:func:`check_operation`).

    References
    ----------
    L. G. Austin, R. R. Klimpel and P. T. Luckie, Process Engineering of Size Reduction:
    Ball Milling (SME-AIME, New York, 1984), ch. 10.

    Examples
    --------
    A 4 m x 6 m mill, 35 % ball filling, 75 % of critical speed (Bond-Rowland gives 1421 kW):

    >>> round(austin_power(4.0, 6.0, 0.35, 0.75)["net_kW"])
    1416
    """
    D, L = _positive(diameter_m, "diameter_m"), _positive(length_m, "length_m")
    check_operation(critical_speed_fraction, ball_filling)
    J, phi = float(ball_filling), float(critical_speed_fraction)
    eps = float(bed_porosity)
    if not (0 < eps < 1):
        raise InputError(f"bed_porosity = {eps!r}: expected 0 < eps < 1")
    rho_b = _positive(ball_density_t_m3, "ball_density_t_m3")
    kw = K * J * phi * (1 - A * J) * (1 - 0.1 / 2 ** (9 - 10 * phi)) * rho_b * L * D ** 2.3 * (1 - eps) / 0.6
    mass_t = ball_charge_mass(D, L, J, rho_b * 1000, eps) / 1000.0
    return {"net_kW": kw, "ball_mass_t": mass_t, "kw_per_t_balls": kw / mass_t}


def charge_arm(ball_filling, radius_m):
    """Distance d_c [m] from the mill axis to the charge's centre of mass.

    Distance d_c [m] from the mill axis to the centre of mass of a charge that fills
    the fraction J of the circular section: a circular segment of half-angle theta with
    (2 theta - sin 2 theta) / (2 pi) = J, and d_c = 4 R sin^3(theta) / (3 (2 theta - sin 2 theta)).
    Exact geometry (a half-full mill gives 4 R / (3 pi)).
    """
    from scipy.optimize import brentq

    J = float(ball_filling)
    if not (0 < J < 1):
        raise InputError(f"ball_filling = {J!r}: expected 0 < J < 1")
    R = _positive(radius_m, "radius_m")
    theta = brentq(lambda t: (2 * t - math.sin(2 * t)) / (2 * math.pi) - J, 0.0, math.pi, xtol=1e-15)
    return 4 * R * math.sin(theta) ** 3 / (3 * (2 * theta - math.sin(2 * theta)))


def hogg_fuerstenau_power(diameter_m, length_m, ball_filling, critical_speed_fraction, ball_size_mm=0.0,
                          ball_density_kg_m3=7800.0, bed_porosity=0.4, repose_angle_deg=35.0):
    """Hogg-Fuerstenau torque-arm power [kW]: P = 2 pi N M_c g d_c sin(alpha).

    N = phi_c N_c [rev/s] (:func:`critical_speed`), M_c the ball-charge mass [kg]
    (:func:`ball_charge_mass`), d_c the arm of the charge's centre of mass
    (:func:`charge_arm`), alpha the dynamic angle of repose of the charge (35 deg default;
    30-45 deg is typical, a property of charge and liner that should be measured).

    Validity: cascading charge (phi_c below ~0.85, no cataracting mass), charge shape a
    flat-surfaced segment; it ignores the powder's contribution (add it via M_c).

    Parameters
    ----------
    diameter_m, length_m : float
        Mill diameter D and length L inside liners [m].
    ball_filling : float
        Fraction J of the mill volume filled by the ball bed (voids included) [-], 0 < J < 0.5.
    critical_speed_fraction : float
        Fraction phi_c of the critical speed [-], 0 < phi_c < 1.
    ball_size_mm : float
        Ball size d [mm] in the critical speed sqrt(2 g / (D - d)) / (2 pi) (0: at the shell).
    ball_density_kg_m3 : float
        Density of the balls [kg/m3].
    bed_porosity : float
        Porosity of the ball bed [-].
    repose_angle_deg : float
        Dynamic angle of repose alpha of the charge [deg].

    Returns
    -------
    dict
        ``net_kW`` [kW], ``ball_mass_t`` [t], ``kw_per_t_balls`` [kW/t].

    Raises
    ------
    InputError
        Dimensions not > 0, or operating fractions outside their range.

    References
    ----------
    R. Hogg and D. W. Fuerstenau, Power relationships for tumbling mills, Trans.
    SME-AIME 252 (1972) 418-423.

    Examples
    --------
    >>> round(hogg_fuerstenau_power(4.0, 6.0, 0.35, 0.75)["net_kW"])
    1282
    """
    D = _positive(diameter_m, "diameter_m")
    check_operation(critical_speed_fraction, ball_filling)
    N = float(critical_speed_fraction) * critical_speed(D, float(ball_size_mm) * 1e-3)
    M = ball_charge_mass(D, length_m, ball_filling, ball_density_kg_m3, bed_porosity)
    dc = charge_arm(ball_filling, D / 2)
    alpha = math.radians(float(repose_angle_deg))
    kw = 2 * math.pi * N * M * G * dc * math.sin(alpha) / 1000.0
    return {"net_kW": kw, "ball_mass_t": M / 1000, "kw_per_t_balls": kw / (M / 1000)}


def gross_power(net_kW, drive_efficiency):
    """Gross (motor input) power [kW] = net / drive efficiency (0 < efficiency <= 1)."""
    e = float(drive_efficiency)
    if not (0 < e <= 1):
        raise InputError(f"drive_efficiency = {e!r}: expected 0 < efficiency <= 1")
    return float(net_kW) / e


POWER_MODELS = {"bond": bond_rowland_power, "austin": austin_power, "hogg_fuerstenau": hogg_fuerstenau_power}


def mill_power(model, **kw):
    """Dispatch by name (one of :data:`POWER_MODELS`) or a callable returning a dict with net_kW."""
    if callable(model):
        return model(**kw)
    if model not in POWER_MODELS:
        raise InputError(f"power_model = {model!r}: expected one of {list(POWER_MODELS)}")
    f = POWER_MODELS[model]
    import inspect
    names = set(inspect.signature(f).parameters)
    return f(**{k: v for k, v in kw.items() if k in names})
