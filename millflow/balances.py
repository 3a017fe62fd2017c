"""Survey balances around one separator: the two- and three-product formulas.

A separator splits a feed F into products whose "assays" (grade of a metal, % passing a
size, or the dilution W/S of water per solids) are measured; the solids balance and one
component balance give the fraction of the feed in each product without weighing any
stream (Wills & Finch, Mineral Processing Technology, 8th ed., ch. 3).

Two products (feed f, product p, other product o of one component)::

    F = P + O,  F f = P p + O o   =>   P/F = (f - o) / (p - o)

Around a classifying cyclone with dilutions (f, u, o of feed, underflow and overflow,
W/S = (1 - C_w)/C_w for C_w the solids mass fraction) the same formula gives the
circulating load, underflow solids over overflow solids (the recycle per unit of new feed
when the overflow is the circuit product)::

    U/O = (o - f) / (f - u)

Three products (two concentrates C1, C2 and a tailing T), with the assays (a, b) of two
components in each stream, from F = C1 + C2 + T and the two component balances::

    (c1_a - t_a) C1/F + (c2_a - t_a) C2/F = f_a - t_a
    (c1_b - t_b) C1/F + (c2_b - t_b) C2/F = f_b - t_b

These are identities of measured data, not predictions; a result outside [0, 1] means the
assays are inconsistent (or the products are too alike to tell apart) and is an InputError.
"""
from __future__ import annotations

import math

from millflow.errors import InputError

__all__ = ["dilution", "two_product", "circulating_load", "three_product"]


def _number(value, name: str, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {name} = {value!r}; expected a finite number") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: {name} = {value!r}; expected a finite number")
    return v


def _share(r: float, name: str, where: str) -> float:
    # exact arithmetic on consistent assays can land a rounding step outside [0, 1]
    if not (-1e-12 <= r <= 1.0 + 1e-12):
        raise InputError(f"{where}: {name} = {r:.6g} lies outside [0, 1]: the assays are inconsistent "
                         "(the feed must lie between the products)")
    return min(max(r, 0.0), 1.0)


def dilution(solids_fraction: float) -> float:
    """Dilution W/S [t water / t solids] of a slurry.

    Parameters
    ----------
    solids_fraction : float
        Solids mass fraction C_w of the slurry [-], in (0, 1].

    Returns
    -------
    float
        W/S = (1 - C_w)/C_w [t water / t solids].

    Raises
    ------
    InputError
        A fraction outside (0, 1] or not a finite number.

    Examples
    --------
    >>> round(dilution(0.6), 6)  # 60 % solids by mass
    0.666667
    """
    c = _number(solids_fraction, "solids_fraction", "dilution")
    if not (0.0 < c <= 1.0):
        raise InputError(f"dilution: solids_fraction = {solids_fraction!r}; expected a mass fraction in (0, 1]")
    return (1.0 - c) / c


def two_product(feed: float, product: float, other: float) -> float:
    """Two-product formula: the fraction of the feed that reports to ``product``.

    P/F = (f - o)/(p - o), from the solids balance F = P + O and the balance of one
    component F f = P p + O o.

    Parameters
    ----------
    feed, product, other : float
        Assays of one component in the feed, that product and the other product (any
        unit, the same for all three: % metal, % passing a size, dilution W/S).

    Returns
    -------
    float
        P/F [-], in [0, 1].

    Raises
    ------
    InputError
        Products of equal assay, or assays that put P/F outside [0, 1] (the feed must lie
        between the products).

    References
    ----------
    B. A. Wills and J. A. Finch, Wills' Mineral Processing Technology, 8th ed.
    (Butterworth-Heinemann, 2016), ch. 3.

    Examples
    --------
    >>> round(two_product(feed=5.0, product=20.0, other=1.0), 6)  # % metal: 4/19 of the feed to the concentrate
    0.210526
    """
    where = "two_product"
    f, p, o = (_number(v, n, where) for v, n in ((feed, "feed"), (product, "product"), (other, "other")))
    if p == o:
        raise InputError(f"{where}: product = other = {p!r}: two products of equal assay cannot be told apart")
    return _share((f - o) / (p - o), "P/F", where)


def circulating_load(feed: float, underflow: float, overflow: float) -> float:
    """Circulating load U/O [-] around a classifier, from assays.

    U/O = (o - f)/(f - u): the two-product formula with the underflow as the product.

    Parameters
    ----------
    feed, underflow, overflow : float
        Assays of one component in the classifier's feed, underflow and overflow:
        dilutions W/S (:func:`dilution`) or the fraction passing one sieve size.

    Returns
    -------
    float
        Underflow solids over overflow solids [-] (the recycle per unit of new feed when
        the overflow is the circuit product).

    Raises
    ------
    InputError
        Inconsistent assays, or a feed assay equal to the underflow's.

    Examples
    --------
    A cyclone fed at 60 % solids, underflow 75 %, overflow 35 %:

    >>> round(circulating_load(dilution(0.60), dilution(0.75), dilution(0.35)), 4)
    3.5714
    """
    r = two_product(feed, underflow, overflow)
    if r >= 1.0:
        raise InputError("circulating_load: the feed assay equals the underflow's; the overflow carries no solids")
    return r / (1.0 - r)


def three_product(feed, concentrate_1, concentrate_2, tailing) -> tuple[float, float, float]:
    """Three-product formula: the feed's split into two concentrates and a tailing.

    Solves the two component balances of the module docstring with F = C1 + C2 + T.

    Parameters
    ----------
    feed, concentrate_1, concentrate_2, tailing : tuple of float
        Assays (a, b) of two components in each stream (any unit, the same for all).

    Returns
    -------
    tuple of float
        (C1/F, C2/F, T/F) [-], each in [0, 1], summing to 1.

    Raises
    ------
    InputError
        Concentrates whose assays are proportional relative to the tailing (they cannot
        be told apart), or shares outside [0, 1] (inconsistent assays).

    Examples
    --------
    >>> c1, c2, t = three_product((3.55, 5.48), (30, 2), (1, 25), (0.5, 0.4))  # % Pb, % Zn
    >>> round(c1, 9), round(c2, 9), round(t, 9)
    (0.1, 0.2, 0.7)
    """
    where = "three_product"
    streams = {"feed": feed, "concentrate_1": concentrate_1, "concentrate_2": concentrate_2, "tailing": tailing}
    v = {}
    for name, pair in streams.items():
        try:
            a, b = pair
        except (TypeError, ValueError):
            raise InputError(f"{where}: {name} = {pair!r}; expected the assays (a, b) of two components") from None
        v[name] = (_number(a, f"{name}[0]", where), _number(b, f"{name}[1]", where))
    (fa, fb), (c1a, c1b), (c2a, c2b), (ta, tb) = v.values()
    det = (c1a - ta) * (c2b - tb) - (c2a - ta) * (c1b - tb)
    scale = max(abs(c1a - ta) * abs(c2b - tb), abs(c2a - ta) * abs(c1b - tb), 1e-300)
    if abs(det) <= 1e-12 * scale:
        raise InputError(f"{where}: the two concentrates have proportional assays relative to the tailing; "
                         "they cannot be told apart (each concentrate must be rich in a different component)")
    r1 = ((fa - ta) * (c2b - tb) - (c2a - ta) * (fb - tb)) / det
    r2 = ((c1a - ta) * (fb - tb) - (fa - ta) * (c1b - tb)) / det
    r1, r2 = _share(r1, "C1/F", where), _share(r2, "C2/F", where)
    return r1, r2, _share(1.0 - r1 - r2, "T/F", where)
