"""The application layer's builders: validated config -> core objects in canonical units.

The one place where units convert (days -> s, degrees -> rad, Isp -> exhaust velocity,
hours -> s, deck sigmas -> canonical units) and where a deck's names are resolved against
the catalogues.  ``trajectory`` builds a :class:`~fracas.integrate.problem.Problem` from a
trajectory deck; ``team`` builds a :class:`~fracas.team.study.Study` from a TEAM deck.
"""

from fracas.build.trajectory import Problem, build_propagation, model_bodies, output_times_s

__all__ = ["Problem", "build_propagation", "model_bodies", "output_times_s"]
