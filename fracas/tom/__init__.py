"""TOM: targeting and final-mass optimization (FRACAS TOM)."""
