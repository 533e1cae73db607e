"""Build the Mercury-approach reference state of namelists/mercury_approach_traj.toml.

A plausible (not optimized) SEP approach: place the spacecraft just outside Mercury's
sphere of influence at the arrival epoch, 2 km/s faster than Mercury along Mercury's
heliocentric velocity with an 8000 km lateral aim offset, and propagate BACKWARD 40 days
with the engine thrusting against the velocity (so the forward trajectory decelerates into
Mercury's neighbourhood).  Prints the initial state of the forward deck.  Run:

    .venv/bin/python scripts/make_mercury_reference.py
"""

import sys
from pathlib import Path

import numpy as np

from fracas import _jax  # noqa: F401
from fracas.build import build_propagation
from fracas.config.trajectory import parse_deck
from fracas.constants import DAY_S
from fracas.dynamics.ephemeris import body_states, build_ephemeris
from fracas.dynamics.parameters import set_values
from fracas.integrate.propagate import propagate

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.runs import exit_if_failed  # noqa: E402  (one shared run-status check)

ARRIVAL = "1985-06-20T00:00:00"
DECK = f"""
[epoch]
iso = "{ARRIVAL}"
[initial_state]
centre = "sun"
frame = "EME2000"
[initial_state.cartesian]
r_km = [1.0e8, 0.0, 0.0]
v_km_s = [0.0, 30.0, 0.0]
[spacecraft]
mass_kg = 1500.0
[propulsion]
power_source = "solar"
power_kw = 3.0
efficiency = 0.65
exhaust_velocity_km_s = 30.0
[[thrust_arc]]
start_days = 0.0
stop_days = 40.0
frame = "velocity"
alpha_deg = 180.0
[forces]
third_bodies = ["mercury", "venus", "earth"]
[integrator]
dt_max_s = 21600.0
[stop]
duration_days = 40.0
"""


def main():
    prob = build_propagation(parse_deck(DECK, "mercury-arrival"))
    et = prob.epoch_et_s
    ephem = build_ephemeris(prob.model.bodies, et - 60 * DAY_S, et + 5 * DAY_S)
    pos, vel = body_states(ephem, et)
    k = prob.model.bodies.index("mercury")
    s = prob.model.bodies.index("sun")
    rm, vm = np.asarray(pos[k] - pos[s]), np.asarray(vel[k] - vel[s])
    d = vm / np.linalg.norm(vm)
    n = np.cross(rm, vm)
    n /= np.linalg.norm(n)
    r_sc = rm - 110_000.0 * d + 8_000.0 * n
    v_sc = vm + 2.0 * d
    x0 = np.concatenate([r_sc, v_sc, [1500.0]])
    params = set_values(prob.params, ["arc_t_on[0]", "arc_t_off[0]"], np.array([-40 * DAY_S, 0.0]), prob.model)
    traj = propagate(prob.model, params, ephem, et, x0, np.array([0.0, -40 * DAY_S]))
    exit_if_failed(traj, "backward propagation", ok=(0,))  # no reference state from an abort point
    x = np.asarray(traj.x[-1])
    print("status", int(traj.status), "; propellant used over the 40 days (kg):", round(float(x[6]) - 1500.0, 4))
    print("r_km =", [round(float(v), 3) for v in x[:3]])
    print("v_km_s =", [round(float(v), 7) for v in x[3:6]])
    print("mass_kg =", round(float(x[6]), 4))


if __name__ == "__main__":
    main()
