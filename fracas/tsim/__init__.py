"""TSIM: Monte Carlo simulation of missions (FRACAS report's TSIM mode).

Core package: pure JAX/numpy numerics, no edge libraries (pydantic, h5py, click, matplotlib,
rich, tomllib).
"""
