"""The optimized reference written back as a trajectory deck (FRACAS TOM's output to $ERTRAJ /
$INSIM): the TOM deck's trajectory with every control's final value written in, as TOML text for
``fracas propagate`` and TEAM's [ertraj].
"""

from __future__ import annotations

import copy
import math

import numpy as np
from numpy.typing import ArrayLike

from fracas import constants
from fracas.build.tom_case import TomCase
from fracas.build.trajectory import _rotation_to_icrf
from fracas.config.trajectory import TrajectoryDeck, load_toml
from fracas.dynamics.model import Params
from fracas.tom.problem import ControlMap


def _wrap_deg(angle_deg: float) -> float:
    """An angle in degrees wrapped to (-180, 180]."""
    w = math.remainder(angle_deg, 360.0)
    return 180.0 if w == -180.0 else w


def _write_oem_state(data: dict, traj: TrajectoryDeck) -> None:
    """A state read from an OEM ([initial_state.oem]) written out as the cartesian state it gave."""
    # a state read from an OEM ([initial_state.oem]) is written out as the cartesian state it
    # gave, with its centre and epoch explicit: the reference deck is written elsewhere, where
    # the OEM's relative path would not resolve, and the OEM may have supplied both
    st0 = traj.initial_state
    if st0.oem is not None:
        ist = data.setdefault("initial_state", {})
        ist.pop("oem", None)
        ist["centre"], ist["frame"] = st0.centre, st0.frame
        ist["cartesian"] = {"r_km": [float(a) for a in st0.oem.r_km], "v_km_s": [float(a) for a in st0.oem.v_km_s]}
        if "epoch" not in data:
            data["epoch"] = traj.epoch.model_dump(mode="json", exclude_none=True)


def _write_initial_state(data: dict, traj: TrajectoryDeck, cm: ControlMap, u: np.ndarray) -> None:
    """The initial state at U, when a state or v∞ control moved it."""
    # initial state (when any state or v∞ control moved it): cartesian in the deck's frame
    if np.any(cm.x0_matrix) or max(cm.vinf_index) >= 0:
        x0 = cm.x0_of(u)
        st = traj.initial_state
        rot = _rotation_to_icrf(st.frame, st.centre)
        r_deck, v_deck = rot.T @ x0[:3], rot.T @ x0[3:6]
        ist = data.setdefault("initial_state", {})
        for key in ("elements", "spherical", "cartesian"):
            ist.pop(key, None)
        ist["cartesian"] = {"r_km": [float(a) for a in r_deck], "v_km_s": [float(a) for a in v_deck]}


def _write_arcs(data: dict, case: TomCase, prm: Params) -> None:
    """The thrust arcs at U: times, mean angles, throttle and (steering) Legendre coefficients."""
    traj, prob = case.trajectory, case.problem
    if case.arcs_rewritten:  # the first guess's arcs replace the deck's
        data["thrust_arc"] = [{"frame": a.frame} for a in traj.thrust_arc]
    arcs = data.get("thrust_arc", [])
    for k, arc in enumerate(arcs):
        arc["start_days"] = float(float(prm.arc_t_on[k]) / constants.DAY_S)
        arc["stop_days"] = float(float(prm.arc_t_off[k]) / constants.DAY_S)
        arc["alpha_deg"] = _wrap_deg(math.degrees(float(prm.arc_alpha[k])))
        arc["beta_deg"] = float(math.degrees(float(prm.arc_beta[k])))
        arc["throttle"] = float(float(prm.arc_throttle[k]))
        if prob.model.steering:
            for angle in ("alpha", "beta"):
                coeffs = [math.degrees(float(getattr(prm, f"arc_{angle}_p{i}")[k])) for i in (1, 2, 3)]
                while coeffs and coeffs[-1] == 0.0:
                    coeffs.pop()
                arc.pop(f"{angle}_legendre_deg", None)
                if coeffs:
                    arc[f"{angle}_legendre_deg"] = coeffs


def _write_impulses_and_stop(data: dict, traj: TrajectoryDeck, cm: ControlMap, u: np.ndarray, prm: Params) -> None:
    """The impulses, the propulsion and the stop (final time, output times) at U."""
    imps = data.get("impulse", [])
    for k, imp in enumerate(imps):
        imp["time_days"] = float(float(prm.impulse_t[k]) / constants.DAY_S)
        imp["dv_km_s"] = [float(float(a)) for a in np.asarray(prm.impulse_dv)[k]]
    if "propulsion" in data:
        pr = data["propulsion"]
        pr.pop("isp_s", None)
        pr["exhaust_velocity_km_s"] = float(float(prm.exhaust_velocity_km_s))
        pr["thrust_scale"] = float(float(prm.thrust_scale))
    if cm.final_time_index >= 0:
        stop = data.setdefault("stop", {})
        stop.pop("final_epoch", None)
        stop["duration_days"] = float(cm.final_time(u) / constants.DAY_S)
    if traj.stop.condition == "time":
        dur = cm.final_time(u) / constants.DAY_S
        out = data.get("output", {})
        if "times_days" in out:
            out["times_days"] = [t for t in out["times_days"] if t <= dur]


def reference_deck_text(case: TomCase, u: ArrayLike) -> str:
    """The trajectory deck of controls U: the TOM deck's trajectory with every control's
    final value written in (TOML text, for ``fracas propagate`` and TEAM's [ertraj])."""
    import tomli_w

    traj = case.trajectory
    data = copy.deepcopy(load_toml(traj.source_text, traj.source_path or "<deck>")) if traj.source_text else {}
    for k in ("tom", "control", "target", "smag", "grid", "trajectory"):
        data.pop(k, None)
    data["mode"] = "propagate"
    prob = case.problem
    cm = prob.controls
    u = np.asarray(u, float)
    prm = prob.params_at(u)
    _write_oem_state(data, traj)
    _write_initial_state(data, traj, cm, u)
    _write_arcs(data, case, prm)
    _write_impulses_and_stop(data, traj, cm, u, prm)
    title = data.get("title", "")
    data["title"] = (title + " (TOM optimum)").strip()
    body = tomli_w.dumps({"mode": data.pop("mode"), "title": data.pop("title"), **data})
    header = (
        "# Written by fracas TOM: the trajectory deck with the converged controls written in.\n"
        f"# TOM deck: {case.deck.source_path or '<deck>'}\n"
    )
    return header + body
