"""Dynamics: conics, forces, propulsion, ephemerides (pure JAX, canonical units km, s, kg, rad)."""
