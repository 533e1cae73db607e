"""Measurement models and partials (FRACAS TRAKM, STAPRL, MENO): pure functions of arrays."""
