"""TRAKM + MENO at the engine boundary: observation_matrix's H against central differences
of its own values (stations perturbed through the Station objects, the spacecraft state
and the body position through Geometry), the bias/QVLBI columns against the label rules
written out here, values against the model functions, R = diag(sigma^2), elevations, and
clear errors for bad input.  (The analytic partials themselves are checked against AD to
1e-12 in test_models.py; here the question is the wiring: chains, signs, scatter.)"""

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest

from fracas import _jax  # noqa: F401
from fracas.measurements.stations import DSN_STATIONS
from fracas.measurements.trakm import (
    Geometry,
    Observation,
    check_measurement_label,
    is_measurement_label,
    measurement_label_unit,
    observation_matrix,
    observation_matrix_many,
)

NX = 7  # r, v, mass
EPS = np.finfo(np.float64).eps
NAMES = ("goldstone", "madrid", "canberra")
STATION_KINDS = (
    "station_radius_km",
    "station_lat_rad",
    "station_lon_rad",
    "range_bias_km",
    "doppler_bias_km_s",
    "azimuth_bias_rad",
    "elevation_bias_rad",
)
LABELS = tuple(f"{k}[{n}]" for k in STATION_KINDS for n in NAMES) + (
    "qvlbi_timing_km",
    "qvlbi_frequency_km_s",
    "star_planet_bias_rad",
    "diameter_bias_rad",
    "mu[sun]",
    "ephem[moon,x]",
)
OBS = (
    Observation("range2", ("goldstone",), 1e-3),
    Observation("range2", ("madrid",), 2e-3),
    Observation("doppler2", ("madrid",), 1e-6),
    Observation("range3", ("goldstone", "canberra"), 1e-2),
    Observation("doppler3", ("madrid", "goldstone"), 1e-7),
    Observation("diff_range", ("goldstone", "canberra"), 1e-2),
    Observation("diff_doppler", ("canberra", "madrid"), 1e-7),
    Observation("azimuth", ("canberra",), 1e-4),
    Observation("elevation", ("goldstone",), 1e-4),
    Observation("star_planet_angle", (), 25e-6),
    Observation("planet_diameter", (), 25e-6),
)
ET = 6.6e8 + 1234.5
D_BODY = np.array([0.3, -0.5, 0.8])  # d body_r / d "ephem[moon,x]" (km per unit)


def _geometry():
    rng = np.random.default_rng(11)
    earth_r = np.array([-2.6e7, 1.33e8, 5.77e7])
    earth_v = np.array([-29.8, -4.9, -2.1])
    d = rng.normal(size=3)
    sc_r = earth_r + 1.5e5 * d / np.linalg.norm(d)
    sc_v = earth_v + rng.normal(size=3)
    s = rng.normal(size=3)
    return Geometry(
        et_s=ET,
        sc_r=sc_r,
        sc_v=sc_v,
        earth_r=earth_r,
        earth_v=earth_v,
        body_r=sc_r + np.array([3.0e4, -2.0e4, 1.0e4]),
        body_v=earth_v,
        body_radius_km=1737.4,
        star_unit=s / np.linalg.norm(s),
        body_r_partials={"ephem[moon,x]": D_BODY},
    )


# Bias rules, written out from the label catalogue (not from trakm): kind -> list of
# (label template, coefficient); {0}/{1} are the observation's stations.
BIAS_RULES = {
    "range2": [("range_bias_km[{0}]", 1.0)],
    "doppler2": [("doppler_bias_km_s[{0}]", 1.0)],
    "range3": [("range_bias_km[{0}]", 1.0), ("range_bias_km[{1}]", 1.0), ("qvlbi_timing_km", 1.0)],
    "doppler3": [("doppler_bias_km_s[{0}]", 1.0), ("doppler_bias_km_s[{1}]", 1.0), ("qvlbi_frequency_km_s", 1.0)],
    "diff_range": [("range_bias_km[{0}]", 1.0), ("range_bias_km[{1}]", -1.0), ("qvlbi_timing_km", -1.0)],
    "diff_doppler": [("doppler_bias_km_s[{0}]", 1.0), ("doppler_bias_km_s[{1}]", -1.0), ("qvlbi_frequency_km_s", -1.0)],
    "azimuth": [("azimuth_bias_rad[{0}]", 1.0)],
    "elevation": [("elevation_bias_rad[{0}]", 1.0)],
    "star_planet_angle": [("star_planet_bias_rad", 1.0)],
    "planet_diameter": [("diameter_bias_rad", 1.0)],
}
BIAS_LABELS = [lab for lab in LABELS if "bias" in lab or lab.startswith("qvlbi")]


@pytest.fixture(scope="module")
def setup():
    geo = _geometry()
    return geo, observation_matrix(OBS, geo, DSN_STATIONS, LABELS, NX)


def _np_station(name, et_s):
    """Station ICRF position/velocity in plain numpy, the ERA in exact rational arithmetic
    (IAU 2000, UT1 = TDB - 69.184 s) so the reference carries no 1e8 s rounding."""
    tu = (Fraction(et_s) - Fraction(69184, 1000)) / 86400
    rev = Fraction("0.7790572732640") + Fraction("1.00273781191135448") * tu
    th = 2.0 * math.pi * float(rev - math.floor(rev))
    s = DSN_STATIONS[name]
    psi = s.longitude_rad + th
    c = math.cos(s.latitude_rad)
    r = s.radius_km * np.array([c * math.cos(psi), c * math.sin(psi), math.sin(s.latitude_rad)])
    w = 2.0 * math.pi * 1.00273781191135448 / 86400.0
    return r, w * np.array([-r[1], r[0], 0.0])


def _np_values(geo):
    """Bias-free values and station elevations (deg) of OBS from textbook formulas in numpy:
    norms, dot products, an explicit ENU matrix, arccos / arcsin."""
    d_r, d_v = geo.sc_r - geo.earth_r, geo.sc_v - geo.earth_v
    vals, elevs = [], []
    for ob in OBS:
        rho, rdot, el, az = [], [], [], []
        for n in ob.stations:
            r, v = _np_station(n, geo.et_s)
            p, w = d_r - r, d_v - v
            rho.append(np.linalg.norm(p))
            rdot.append(p @ w / rho[-1])
            lam, phi = math.atan2(r[1], r[0]), math.atan2(r[2], math.hypot(r[0], r[1]))
            enu = np.array(
                [
                    [-math.sin(lam), math.cos(lam), 0.0],
                    [-math.sin(phi) * math.cos(lam), -math.sin(phi) * math.sin(lam), math.cos(phi)],
                    [math.cos(phi) * math.cos(lam), math.cos(phi) * math.sin(lam), math.sin(phi)],
                ]
            )
            e, nn, u = enu @ p
            az.append(math.atan2(e, nn) % (2 * math.pi))
            el.append(math.asin(u / rho[-1]))
        q = geo.body_r - geo.sc_r
        if ob.kind == "star_planet_angle":
            vals.append(math.acos(geo.star_unit @ q / np.linalg.norm(q)))
        elif ob.kind == "planet_diameter":
            vals.append(2 * math.asin(geo.body_radius_km / np.linalg.norm(q)))
        else:
            vals.append(
                {
                    "range2": rho[0],
                    "doppler2": rdot[0],
                    "azimuth": az[0],
                    "elevation": el[0],
                    "range3": sum(rho),
                    "doppler3": sum(rdot),
                    "diff_range": rho[0] - rho[-1],
                    "diff_doppler": rdot[0] - rdot[-1],
                }[ob.kind]
            )
        elevs.append(math.degrees(min(el)) if el else math.nan)
    return np.array(vals), np.array(elevs)


def test_values_are_the_bias_free_model_values(setup):
    # Independent float64 formulas: the naive differences lose ~1.5 digits here (rho 1.5e5
    # km, differences ~1e4 km), arccos/arcsin are well conditioned at these angles, so
    # agreement is ~1e-14 relative; tolerance 1e-12 relative (+1e-15 absolute).
    geo, batch = setup
    ref, _ = _np_values(geo)
    assert np.all(np.abs(batch.values - ref) <= 1e-12 * np.abs(ref) + 1e-15), batch.values - ref


def test_bias_and_parameter_columns_follow_the_label_rules(setup):
    # Unit partials, exactly (TRAKM eq. 8 and its closing remark on angle biases): the whole
    # bias/QVLBI block of H equals the one built from BIAS_RULES; columns of parameters no
    # measurement depends on (mass, mu[sun]) and velocity partials of ranges and angles
    # are exactly zero; the ephemeris label is zero for Earth-based kinds.
    _, batch = setup
    H = batch.H
    col = {lab: NX + j for j, lab in enumerate(LABELS)}
    expected = np.zeros((len(OBS), len(BIAS_LABELS)))
    for i, ob in enumerate(OBS):
        for template, coef in BIAS_RULES[ob.kind]:
            expected[i, BIAS_LABELS.index(template.format(*ob.stations))] += coef
    assert np.array_equal(H[:, [col[lab] for lab in BIAS_LABELS]], expected)
    assert np.all(H[:, 6] == 0.0) and np.all(H[:, col["mu[sun]"]] == 0.0)
    for i, ob in enumerate(OBS):
        if ob.kind in (
            "range2",
            "range3",
            "diff_range",
            "azimuth",
            "elevation",
            "star_planet_angle",
            "planet_diameter",
        ):
            assert np.all(H[i, 3:6] == 0.0), ob
        if ob.stations:
            assert H[i, col["ephem[moon,x]"]] == 0.0, ob


def test_H_matches_central_differences_of_values(setup):
    # FD of observation_matrix's own values, perturbing the inputs as a caller would: the
    # Station objects (dataclasses.replace) for station labels, Geometry for the spacecraft
    # state and body_r for the ephemeris label.  Steps and error budget (spacecraft 1.5e5 km
    # from Earth, all values smooth on the station-radius scale):
    #   station R 1e-2 km, angles 1e-6 rad: truncation ~h^2|f'''|/6 < 1e-10 of the partial,
    #     rounding eps |f| / h < 1e-16 * 1.5e5 / 1e-2 ~ 2e-9 km/km;
    #   spacecraft r 1 km: the heliocentric sc_r (~1.5e8 km) rounds sc_r + h by up to
    #     1.5e-8 km, i.e. 1.5e-8 relative error in the step; truncation h^2/rho^2 ~ 4e-11;
    #   spacecraft v 1e-4 km/s, ephemeris 1 km: values linear or nearly so.
    # Tolerance 1e-6 of each row's largest entry in the same column group: 50x above the
    # worst budget item, far below any wrong sign or missing term.
    geo, batch = setup
    H = batch.H
    col = {lab: NX + j for j, lab in enumerate(LABELS)}

    def values(geometry=geo, stations=DSN_STATIONS):
        return observation_matrix(OBS, geometry, stations, LABELS, NX).values

    def check(cols_fd, cols, h):
        # plus a rounding floor 100 eps |f| / h for partials that vanish (e.g. azimuth vs R)
        a, b = np.array(cols_fd).T, H[:, cols]
        for i in range(len(OBS)):
            tol = 1e-6 * np.max(np.abs(b[i])) + 100 * EPS * abs(batch.values[i]) / h
            assert np.max(np.abs(a[i] - b[i])) <= tol, (OBS[i], a[i], b[i])

    for field, label, h in (
        ("radius_km", "station_radius_km", 1e-2),
        ("latitude_rad", "station_lat_rad", 1e-6),
        ("longitude_rad", "station_lon_rad", 1e-6),
    ):
        fd = []
        for n in NAMES:
            s0 = DSN_STATIONS[n]
            plus = dict(DSN_STATIONS, **{n: dataclasses.replace(s0, **{field: getattr(s0, field) + h})})
            minus = dict(DSN_STATIONS, **{n: dataclasses.replace(s0, **{field: getattr(s0, field) - h})})
            fd.append((values(stations=plus) - values(stations=minus)) / (2 * h))
        check(fd, [col[f"{label}[{n}]"] for n in NAMES], h)

    for attr, sl, h in (("sc_r", slice(0, 3), 1.0), ("sc_v", slice(3, 6), 1e-4)):
        fd = []
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            gp = dataclasses.replace(geo, **{attr: getattr(geo, attr) + e})
            gm = dataclasses.replace(geo, **{attr: getattr(geo, attr) - e})
            fd.append((values(geometry=gp) - values(geometry=gm)) / (2 * h))
        check(fd, list(range(sl.start, sl.stop)), h)

    gp = dataclasses.replace(geo, body_r=geo.body_r + D_BODY)
    gm = dataclasses.replace(geo, body_r=geo.body_r - D_BODY)
    check([(values(geometry=gp) - values(geometry=gm)) / 2.0], [col["ephem[moon,x]"]], 1.0)


def test_noise_covariance_and_elevations(setup):
    # MENO: R = diag(sigma^2) exactly.  Elevations: the lowest of the participating stations
    # (degrees; numpy reference), nan for spacecraft-based kinds.
    geo, batch = setup
    sig = np.array([ob.sigma for ob in OBS])
    assert np.array_equal(batch.R, np.diag(sig**2))
    _, ref = _np_values(geo)
    assert np.array_equal(np.isnan(batch.elevation_deg), [not ob.stations for ob in OBS])
    ok = ~np.isnan(ref)
    assert np.max(np.abs(batch.elevation_deg[ok] - ref[ok])) < 1e-10  # deg; asin well conditioned
    # stations on opposite sides of the Earth: at least one is below the horizon, not fatal
    assert np.nanmin(batch.elevation_deg) < 0.0


def test_padding_and_grouping_do_not_change_rows(setup):
    # Six range2 observations (padded bucket of 8), a reversed mixed batch and a two-epoch
    # batch give the same rows as the per-epoch calls: bookkeeping only, so bit-identical.
    geo, batch = setup
    many = observation_matrix([OBS[0], OBS[1]] * 3, geo, DSN_STATIONS, LABELS, NX)
    assert np.array_equal(many.H[0::2], np.repeat(batch.H[0:1], 3, axis=0))
    assert np.array_equal(many.H[1::2], np.repeat(batch.H[1:2], 3, axis=0))
    rev = observation_matrix(OBS[::-1], geo, DSN_STATIONS, LABELS, NX)
    assert np.array_equal(rev.H, batch.H[::-1]) and np.array_equal(rev.values, batch.values[::-1])
    # many epochs in one call: interleaved rows equal the per-epoch calls
    geo2 = dataclasses.replace(
        geo, et_s=geo.et_s + 3600.0, sc_r=geo.sc_r + 500.0, body_r_partials={"ephem[moon,x]": 2.0 * D_BODY}
    )
    one2 = observation_matrix(OBS, geo2, DSN_STATIONS, LABELS, NX)
    both = observation_matrix_many([(ob, g) for ob in OBS for g in (geo, geo2)], DSN_STATIONS, LABELS, NX)
    assert np.array_equal(both.H[0::2], batch.H) and np.array_equal(both.H[1::2], one2.H)
    assert np.array_equal(both.values[1::2], one2.values)
    assert np.array_equal(np.isnan(both.elevation_deg[1::2]), np.isnan(one2.elevation_deg))


# --- labels and validation ----------------------------------------------------------------
def test_label_helpers():
    assert is_measurement_label("range_bias_km[goldstone]")
    assert is_measurement_label("qvlbi_timing_km")
    assert not is_measurement_label("mu[sun]")
    assert not is_measurement_label("range_bias_km")  # needs a station
    assert not is_measurement_label("qvlbi_timing_km[goldstone]")  # takes none
    units = {
        "station_radius_km[x]": "km",
        "station_lat_rad[x]": "rad",
        "station_lon_rad[x]": "rad",
        "range_bias_km[x]": "km",
        "doppler_bias_km_s[x]": "km/s",
        "azimuth_bias_rad[x]": "rad",
        "elevation_bias_rad[x]": "rad",
        "qvlbi_timing_km": "km",
        "qvlbi_frequency_km_s": "km/s",
        "star_planet_bias_rad": "rad",
        "diameter_bias_rad": "rad",
    }
    for lab, unit in units.items():
        assert measurement_label_unit(lab) == unit
    with pytest.raises(KeyError, match="valid forms"):
        measurement_label_unit("thrust_scale")
    check_measurement_label("elevation_bias_rad[madrid]", NAMES)
    with pytest.raises(KeyError, match="'parkes' is not one of canberra, goldstone, madrid"):
        check_measurement_label("range_bias_km[parkes]", NAMES)
    with pytest.raises(KeyError, match=r"range_bias_km\[<station>\]"):
        check_measurement_label("range_bias_km", NAMES)


def test_observation_validation():
    with pytest.raises(ValueError, match="unknown: expected one of range2"):
        Observation("range", ("goldstone",), 1e-3)
    with pytest.raises(ValueError, match="diff_range needs 2 station"):
        Observation("diff_range", ("goldstone",), 1e-3)
    with pytest.raises(ValueError, match="star_planet_angle needs 0 station"):
        Observation("star_planet_angle", ("goldstone",), 1e-5)
    with pytest.raises(ValueError, match="must differ"):
        Observation("range3", ("madrid", "madrid"), 1e-3)
    with pytest.raises(ValueError, match="sigma must be positive"):
        Observation("range2", ("madrid",), 0.0)
    with pytest.raises(ValueError, match="tuple of names"):
        Observation("range2", "madrid", 1e-3)


def test_observation_matrix_errors(setup):
    geo = setup[0]
    with pytest.raises(KeyError, match="station 'parkes' unknown"):
        observation_matrix([Observation("range2", ("parkes",), 1e-3)], geo, DSN_STATIONS, LABELS, NX)
    with pytest.raises(KeyError, match="'parkes' is not one of"):
        observation_matrix(OBS[:1], geo, DSN_STATIONS, ["range_bias_km[parkes]"], NX)
    with pytest.raises(KeyError, match="unknown measurement-parameter label 'doppler_bias_km_s'"):
        observation_matrix(OBS[:1], geo, DSN_STATIONS, ["doppler_bias_km_s"], NX)
    with pytest.raises(ValueError, match="nx must be >= 6"):
        observation_matrix(OBS[:1], geo, DSN_STATIONS, LABELS, 3)
    with pytest.raises(ValueError, match="needs Geometry.body_r"):
        observation_matrix(OBS[-1:], dataclasses.replace(geo, body_r=None), DSN_STATIONS, LABELS, NX)
    with pytest.raises(ValueError, match=r"Geometry.sc_r: expected shape \(3,\)"):
        observation_matrix(OBS[:1], dataclasses.replace(geo, sc_r=np.zeros(6)), DSN_STATIONS, LABELS, NX)
