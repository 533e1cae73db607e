"""The layout of the TEAM results file and the punch file (``docs/team_results.md``) that
their writer (:mod:`fracas.io.team_results`) and their reader
(:mod:`fracas.io.team_results_read`) share: schema versions, the groups and measurement
fields every results file has, the guidance datasets with their units.
"""

from __future__ import annotations

RESULTS_SCHEMA = 2  # 2: every dataset carries data_sha256; 1 (no checksums) is still read
PUNCH_SCHEMA = 2
# groups and measurement fields every results file has had (schema 1 included) and the report reads
_TEAM_GROUPS = ("team", "team/labels", "team/measurements", "team/assumed", "team/assumed/eigenvector_events")
_MEASUREMENT_FIELDS = (
    "index",
    "tracking",
    "type",
    "stations",
    "value",
    "elevation_deg",
    "used",
    "sigma",
    "innovation_sigma",
)


_GUIDANCE_MATRICES = (
    ("psi", "targets x labels/units", "target variation matrix at the cutoff (TARMAT)"),
    ("gamma", "controls x labels/units", "guidance law: correction = -gamma @ estimated deviation"),
    ("target_cov_before", "target units^2", "dispersion at the target time without the correction (noise included)"),
    ("target_cov_after", "target units^2", "dispersion at the target time after the correction (noise included)"),
    ("target_cov_knowledge", "target units^2", "knowledge covariance at the event mapped to the target"),
    ("target_noise_cov", "target units^2", "process noise from the cutoff to the target time, at the targets"),
    ("correction_cov", "control units^2", "covariance of the correction (dV km^2/s^2, or controls)"),
    ("execution_cov", "control units^2", "execution-error covariance"),
)
#: guidance datasets a file may lack (written before they existed): read as None
_GUIDANCE_OPTIONAL = ("target_noise_cov",)
_GUIDANCE_SCALARS = ("dv_mean_km_s", "dv_99_km_s", "dv_rms_km_s", "propellant_sigma_kg", "dv_variance_km2_s2")
_SCALAR_UNITS = {"propellant_sigma_kg": "kg", "dv_variance_km2_s2": "km^2/s^2"}
