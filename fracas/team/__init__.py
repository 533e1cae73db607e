"""TEAM: linear covariance error analysis (event schedule, STM file reuse, generalized covariance)."""
