"""Guidance numerics (FRACAS GUIDM §5.3.6, XGUID §5.3.25): pure functions of arrays.

``impulsive``: the linear impulsive guidance law, its ΔV and execution-error covariances and
the post-maneuver control and target covariances.  ``statistics``: mean and quantiles of |ΔV|
from the ΔV covariance.  Not yet wired into the TEAM engine.
"""
