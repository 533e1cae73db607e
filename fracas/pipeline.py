"""Temporary: the orchestrators moved to :mod:`fracas.modes` (one module a mode)."""

from fracas.build.trajectory_product import describe_integrator, trajectory_data
from fracas.modes import load_any
from fracas.modes.base import Stage, beside, default_output
from fracas.modes.propagate import propagate_deck, run_propagation
from fracas.modes.rendezvous import run_rendezvous
from fracas.modes.stm import build_stm, load_team, read_reference, reference_from_stm, stm_product
from fracas.modes.team import run_team
from fracas.modes.tom import run_tom, tom_outputs

__all__ = [
    "Stage",
    "beside",
    "build_stm",
    "default_output",
    "describe_integrator",
    "load_any",
    "load_team",
    "propagate_deck",
    "read_reference",
    "reference_from_stm",
    "run_propagation",
    "run_rendezvous",
    "run_team",
    "run_tom",
    "stm_product",
    "tom_outputs",
    "trajectory_data",
]
