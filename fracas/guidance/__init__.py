"""Guidance numerics (FRACAS GUIDM §5.3.6, XGUID §5.3.25, TARMAT §5.4.9): functions of arrays.

``impulsive``: the linear impulsive guidance law, its ΔV and execution-error covariances and
the post-maneuver control and target covariances.  ``statistics``: mean and quantiles of |ΔV|
from the ΔV covariance.  ``target_kinds``: the jax-free catalogue of target names and units.
``targets``: target values, A_T = ∂T/∂X_f, Ψ = A_T Φ and Ψ_p = A_T Θ (TARMAT), TARPRL's
element partials.  ``low_thrust``: the low-thrust primary guidance controls, their
sensitivity S, the weighted correction matrix Γ_U, cost Jacobians and execution errors.
Not yet wired into the TEAM engine.
"""
