"""Integration: the Encke/Nystrom propagator, sensitivities (STM, parameter matrix), batches."""
