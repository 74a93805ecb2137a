"""The refractive index of sea water from its salinity, temperature and the wavelength.

Quan and Fry's empirical equation (X. Quan and E. S. Fry, "Empirical equation for the index of
refraction of seawater", Applied Optics 34(18), 3477-3480, 1995), a ten-parameter fit to the data
that Austin and Halikas selected ("The index of refraction of seawater", SIO Ref. 76-1, Scripps
Institution of Oceanography, 1976)::

    n(S, T, lambda) = n0 + (n1 + n2 T + n3 T^2) S + n4 T^2
                      + (n5 + n6 S + n7 T) / lambda + n8 / lambda^2 + n9 / lambda^3

with ``S`` the salinity (psu; Austin and Halikas's parts per thousand), ``T`` the temperature
(degrees Celsius) and ``lambda`` the wavelength in vacuum (nm), at atmospheric pressure. The index
is relative to air, which is what a port model with ``n_air = 1`` needs: only the ratios of the
indices enter refraction. The equation holds for 0-35 psu, 0-30 C and 400-700 nm; outside it is
an extrapolation, refused here.
"""

from __future__ import annotations

from lfrefract.errors import ParameterError
from lfrefract.validate import finite_float

__all__ = [
    "SALINITY_RANGE_PSU",
    "SODIUM_D_NM",
    "TEMPERATURE_RANGE_C",
    "WAVELENGTH_RANGE_NM",
    "seawater_index",
]

#: Validity ranges of Quan and Fry's equation (closed intervals).
SALINITY_RANGE_PSU = (0.0, 35.0)
TEMPERATURE_RANGE_C = (0.0, 30.0)
WAVELENGTH_RANGE_NM = (400.0, 700.0)

#: The sodium D line, nm: the wavelength refractive indices are usually quoted at.
SODIUM_D_NM = 589.3

# The coefficients n0 .. n9 of Quan and Fry (1995).
_N = (1.31405, 1.779e-4, -1.05e-6, 1.6e-8, -2.02e-6, 15.868, 0.01155, -0.00423, -4382.0, 1.1455e6)


def _in_range(name: str, value, bounds: tuple[float, float], unit: str) -> float:
    out = finite_float(name, value)
    lo, hi = bounds
    if not lo <= out <= hi:
        raise ParameterError(
            f"{name}={value!r} is outside the range of Quan and Fry's equation for the index of sea "
            f"water ({lo:g} to {hi:g} {unit})"
        )
    return out


def seawater_index(
    *,
    salinity_psu: float,
    temperature_c: float,
    wavelength_nm: float = SODIUM_D_NM,
) -> float:
    """Refractive index of sea water relative to air (Quan and Fry 1995; see the module docstring).

    Parameters
    ----------
    salinity_psu : float
        Practical salinity, 0 to 35 (0: fresh water).
    temperature_c : float
        Temperature, degrees Celsius, 0 to 30.
    wavelength_nm : float
        Wavelength in vacuum, nanometres, 400 to 700 (default: the sodium D line, 589.3 nm).

    Returns
    -------
    float
        The index, about 1.329 to 1.352 over the valid ranges.

    Raises
    ------
    ParameterError
        If a value is not a finite number or lies outside the equation's range; the message names
        the parameter and the value.
    """
    s = _in_range("salinity_psu", salinity_psu, SALINITY_RANGE_PSU, "psu")
    t = _in_range("temperature_c", temperature_c, TEMPERATURE_RANGE_C, "C")
    lam = _in_range("wavelength_nm", wavelength_nm, WAVELENGTH_RANGE_NM, "nm")
    n0, n1, n2, n3, n4, n5, n6, n7, n8, n9 = _N
    return n0 + (n1 + n2 * t + n3 * t * t) * s + n4 * t * t + (n5 + n6 * s + n7 * t) / lam + n8 / lam**2 + n9 / lam**3
