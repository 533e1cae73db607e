"""Labelled access into :class:`fracas.dynamics.model.Params` (JAX; differentiable).

Labels and their meaning are the catalogue :mod:`fracas.params`; these two functions read
and replace the labelled entries of a ``Params`` pytree.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import jax.numpy as jnp
from jax import Array

from fracas import _jax  # noqa: F401
from fracas.dynamics.model import ForceModel, Params
from fracas.params import parse_label

if TYPE_CHECKING:
    import numpy as np

__all__ = ["get_values", "set_values"]


def get_values(params: Params, labels: Sequence[str], model: ForceModel) -> Array:
    """Current values of the labelled parameters as one float64 vector."""
    vals = []
    for label in labels:
        name, idx = parse_label(label, model)
        vals.append(jnp.asarray(getattr(params, name), jnp.float64)[idx])
    return jnp.stack(vals) if vals else jnp.zeros(0)


def set_values(params: Params, labels: Sequence[str], values: Array | np.ndarray, model: ForceModel) -> Params:
    """Params with the labelled entries replaced by ``values`` (differentiable in ``values``)."""
    upd: dict[str, Array] = {}
    for j, label in enumerate(labels):
        name, idx = parse_label(label, model)
        cur = upd.get(name, jnp.asarray(getattr(params, name), jnp.float64))
        upd[name] = cur.at[idx].set(values[j]) if idx else values[j] + 0.0 * cur
    return params._replace(**upd)
