"""Stage products: frozen, labelled objects that pass from stage to stage.

A product holds arrays with their labels, units, epochs and provenance, and nothing that
points back at a deck or at engine state.  ``fracas.io`` serialises products and reads them
back; ``fracas.report`` reads the files.  This package is numpy-only (no jax, h5py or
pydantic), so every layer may import it.  One module per product family:

* :mod:`~fracas.products.reference` -- :class:`ReferenceTrajectory`, a reference trajectory
  sampled at the times analyses need, with Phi and Theta between consecutive times (the STM
  file's contents, FRACAS STMGEN); :func:`chain` multiplies its step matrices over skipped
  times (STMRDR, section 3.2).
* :mod:`~fracas.products.team` -- :class:`TeamProduct`, the covariance history of one TEAM
  run (``fracas.team.result``), and its parts.
* :mod:`~fracas.products.trajectory` -- :class:`TrajectoryData`, one propagation with its
  optional :class:`SensitivityData` (``fracas.build.trajectory_product.trajectory_data``;
  the trajectory file's contents).
* :mod:`~fracas.products.tom` -- :class:`TomProduct`, one TOM run: controls, targets, final
  mass, iteration history.
* :mod:`~fracas.products.tsim` -- :class:`TsimProduct` and :class:`TsimManeuver`, one TSIM
  Monte Carlo run.
* :mod:`~fracas.products.rendezvous` -- :class:`RendezvousProduct`, one two-vehicle
  navigation run.
"""

from __future__ import annotations

from fracas.products.reference import (
    SCHEMA_VERSION,
    TIME_TOL_S,
    ReferenceTrajectory,
    chain,
    time_indices,
)
from fracas.products.reference import _days as _days
from fracas.products.reference import _indices as _indices
from fracas.products.rendezvous import RendezvousProduct
from fracas.products.team import (
    ControlHistory,
    CovarianceHistory,
    EigenEvents,
    ErrorBudget,
    GuidanceEvent,
    MeasurementLog,
    Prediction,
    TeamProduct,
)
from fracas.products.tom import TomProduct
from fracas.products.trajectory import SensitivityData, TrajectoryData
from fracas.products.tsim import TsimManeuver, TsimProduct

__all__ = [
    "ReferenceTrajectory",
    "TeamProduct",
    "GuidanceEvent",
    "ControlHistory",
    "ErrorBudget",
    "TrajectoryData",
    "SensitivityData",
    "TomProduct",
    "chain",
    "time_indices",
    "SCHEMA_VERSION",
    "TIME_TOL_S",
    # also imported by other modules
    "EigenEvents",
    "CovarianceHistory",
    "MeasurementLog",
    "Prediction",
    "TsimManeuver",
    "TsimProduct",
    "RendezvousProduct",
]
