"""The catalogues: parameters and state (fracas.params) and measurement kinds
(fracas.measurements.kinds) are jax-free, self-consistent, and the one source that config,
core, I/O and the measurement models read."""

from __future__ import annotations

import subprocess
import sys
import typing
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fracas import constants, params
from fracas.measurements import kinds

ROOT = Path(__file__).resolve().parents[1]
BODIES = ("sun", "earth", "mars")
N_ARCS, N_IMPULSES = 2, 2


def _model():
    from fracas.dynamics.model import ForceModel, IntegratorSettings

    return ForceModel(
        bodies=BODIES,
        primary=0,
        third_bodies=(1, 2),
        thrust=True,
        n_arcs=N_ARCS,
        n_impulses=N_IMPULSES,
        conic_bodies=(2,),
        integrator=IntegratorSettings(c_nom=0.05),
    )


def _labels(kind: params.ParamKind) -> list[str]:
    """Every label of one kind that the test model admits."""
    n = kind.name
    if kind.index == params.INDEX_SCALAR:
        return [n]
    if kind.index == params.INDEX_BODY:
        return [f"{n}[{b}]" for b in BODIES]
    if kind.index == params.INDEX_BODY_ELEMENT:
        return [f"{n}[{b},{e}]" for b in BODIES for e in params.ELEMENT_NAMES]
    if kind.index == params.INDEX_ARC:
        return [f"{n}[{k}]" for k in range(N_ARCS)]
    if kind.index == params.INDEX_IMPULSE:
        return [f"{n}[{k}]" for k in range(N_IMPULSES)]
    assert kind.index == params.INDEX_IMPULSE_AXIS
    return [f"{n}[{k},{a}]" for k in range(N_IMPULSES) for a in range(3)]


# --- jax-free imports -----------------------------------------------------------------
def test_catalogues_import_without_jax_or_dynamics():
    code = (
        "import sys\n"
        "import fracas.params, fracas.measurements.kinds, fracas.measurements, fracas.config.team\n"
        "bad = sorted(m for m in sys.modules if m == 'jax' or m.startswith(('jax.', 'fracas.dynamics')))\n"
        "assert not bad, bad\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_measurements_package_still_exports_every_name_lazily():
    import fracas.measurements as M
    from fracas.measurements import models, stations, trakm

    for name in M.__all__:
        assert getattr(M, name) is not None, name
    assert M.Observation is trakm.Observation and M.DSN_STATIONS is stations.DSN_STATIONS
    assert M.KINDS is models.KINDS is kinds.KINDS
    assert M.is_measurement_label is trakm.is_measurement_label is kinds.is_measurement_label


# --- parameters -----------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(params.PARAMETER_KINDS))
def test_every_parameter_kind_has_a_unit_index_and_sane_bounds(name):
    k = params.PARAMETER_KINDS[name]
    assert k.name == name and k.index in params.INDEX_KINDS and k.description
    if k.index == params.INDEX_BODY_ELEMENT:
        assert len(k.unit) == len(params.ELEMENT_NAMES) and all(k.unit)
    else:
        assert isinstance(k.unit, str) and k.unit
    lo, hi = k.bounds
    assert lo is None or hi is None or lo <= hi
    assert k.sigma is None or k.sigma > 0.0


def test_every_accepted_label_maps_to_a_params_field():
    from fracas.dynamics.model import Params, default_params

    model = _model()
    p = default_params(model)
    n = 0
    for k in params.PARAMETER_KINDS.values():
        assert k.field in Params._fields
        for label in _labels(k):
            field, idx = params.parse_label(label, model)
            assert field == k.field
            value = np.asarray(getattr(p, field), np.float64)[idx]
            assert value.shape == (), label  # one scalar per label
            assert params.param_unit(label, model) == k.unit_at(idx)
            assert params.parameter_kind(label, model) is k
            n += 1
    assert n > 50


def test_parse_label_only_needs_bodies_arcs_and_impulses():
    duck = SimpleNamespace(bodies=("earth", "moon"), n_arcs=1, n_impulses=0)
    assert params.parse_label("mu[moon]", duck) == ("mu", (1,))
    assert params.parse_label("arc_throttle[0]", duck) == ("arc_throttle", (0,))
    with pytest.raises(KeyError, match=r"arc 1 does not exist \(1 thrust arcs\)"):
        params.parse_label("arc_throttle[1]", duck)
    with pytest.raises(KeyError, match="unknown parameter 'nope'; known: "):
        params.parse_label("nope", duck)


def test_get_and_set_values_live_in_dynamics_only():
    """The catalogue names parameters; reading and writing their values (JAX) is the core's
    (fracas.dynamics.parameters), with no second entry point in the catalogue."""
    from fracas.dynamics import parameters

    assert callable(parameters.get_values) and callable(parameters.set_values)
    assert not hasattr(params, "get_values") and not hasattr(params, "set_values")


def test_state_and_thrust_noise_labels_are_defined_once():
    from fracas.integrate import variational
    from fracas.io import stm_file, trajectory_file

    assert params.STATE_LABELS == ("x", "y", "z", "vx", "vy", "vz", "mass")
    assert len(params.STATE_UNITS) == len(params.STATE_LABELS)
    assert trajectory_file.STATE_LABELS is stm_file.STATE_LABELS is params.STATE_LABELS
    assert trajectory_file.STATE_UNITS is stm_file.STATE_UNITS is params.STATE_UNITS
    assert variational.THRUST_NOISE_LABELS is params.THRUST_NOISE_LABELS
    model = _model()
    for label in params.THRUST_NOISE_LABELS:
        assert params.PARAMETER_KINDS[params.parse_label(label, model)[0]].index == params.INDEX_SCALAR


def test_deck_roles_are_the_catalogue_roles():
    from fracas.config.team import Parameter

    assert typing.get_args(Parameter.model_fields["role"].annotation) == params.DECK_ROLES
    assert set(params.DECK_ROLES) - {params.ROLE_CONSIDER} < set(params.AUGMENTED_ROLES)
    assert params.AUGMENTED_ROLES == ("solve_for", "dynamic_consider", "measurement_consider", "ignore")


def test_day_constants_agree():
    assert isinstance(constants.SECONDS_PER_DAY, int)
    assert float(constants.SECONDS_PER_DAY) == constants.DAY_S == 86400.0
    from fracas.io import stm_file

    assert stm_file.DAY_S is constants.DAY_S


# --- measurement kinds ------------------------------------------------------------------
def test_every_measurement_kind_has_a_model_and_vice_versa():
    from fracas.measurements import models

    assert set(kinds.MEASUREMENT_KINDS) == set(models.VALUE_FUNCTIONS) == set(models.PARTIAL_FUNCTIONS)
    assert models.KINDS == kinds.KINDS and models.N_STATIONS == kinds.N_STATIONS


@pytest.mark.parametrize("name", kinds.KINDS)
def test_every_measurement_kind_is_complete(name):
    k = kinds.MEASUREMENT_KINDS[name]
    assert k.name == name and k.unit in ("km", "km/s", "rad") and k.description and k.trakm_name
    assert k.sigma_unit and k.sigma_factor > 0.0
    assert k.needs_body == (k.n_stations == 0)
    assert not k.needs_star or k.needs_body
    assert k.bias_terms
    for label, slot, coef in k.bias_terms:  # each bias term is a catalogued label of the right form
        p = kinds.MEASUREMENT_PARAMETERS[label]
        assert p.per_station == (slot is not None)
        assert slot is None or slot < k.n_stations
        assert p.unit == k.unit and coef in (1.0, -1.0)


def test_sigma_units_and_types_in_config_are_the_catalogue():
    from fracas.config import team

    assert team.MEASUREMENT_TYPES == kinds.KINDS
    assert team.N_STATIONS == kinds.N_STATIONS
    assert set(team.SIGMA_UNITS) == set(kinds.MEASUREMENT_KINDS)
    for name, (unit, factor) in team.SIGMA_UNITS.items():
        k = kinds.MEASUREMENT_KINDS[name]
        assert (unit, factor) == (k.sigma_unit, k.sigma_factor)
    assert team.SIGMA_UNITS["azimuth"][1] == np.deg2rad(1.0)


def test_measurement_parameter_labels_and_units_come_from_the_catalogue():
    from fracas.measurements import trakm

    assert trakm.STATION_LABELS is kinds.STATION_LABELS and trakm.GLOBAL_LABELS is kinds.GLOBAL_LABELS
    assert trakm._KIND_UNITS == {k.name: k.unit for k in kinds.MEASUREMENT_KINDS.values()}
    assert set(trakm._BIAS_TERMS) == set(kinds.KINDS)
    for p in kinds.MEASUREMENT_PARAMETERS.values():
        label = f"{p.name}[goldstone]" if p.per_station else p.name
        assert kinds.is_measurement_label(label)
        assert kinds.measurement_label_unit(label) == p.unit
        kinds.check_measurement_label(label, ["goldstone"])
        assert not kinds.is_measurement_label(p.name if p.per_station else f"{p.name}[goldstone]")
    assert set(kinds.MEASUREMENT_PARAMETERS).isdisjoint(params.PARAMETER_KINDS)
