"""Legacy FRACAS namelist decks <-> fracas TOML decks (``fracas import-namelist``).

FRACAS (report §3) reads its input by namelists: ``$DATA`` and ``$SMAG`` (TOM, §3.1),
``$ERRCON``, ``$ERTRAJ``, ``$ERANAL`` and ``$GENCOV`` (TEAM, §3.2), ``$INSIM`` and one
``$INMAN`` per maneuver (TSIM, §3.3).  The report lists what each namelist holds but not the
variable names (the input-description pages of the scan carry no names), so the names used
here are fracas's own, chosen in the FRACAS style (upper case, at most six characters, codes
as small integers, arrays indexed from 1) and listed in ``docs/namelist.md``; the tables
:data:`TRAJECTORY_FIELDS`, :data:`TOM_FIELDS`, :data:`SMAG_FIELDS`, :data:`ERRCON_FIELDS`,
:data:`ERTRAJ_FIELDS`, :data:`ERANAL_FIELDS`, :data:`GENCOV_FIELDS`, :data:`INSIM_FIELDS`
and :data:`INMAN_FIELDS` are the mapping, both ways.

Units of a namelist deck (FRACAS works in km, s, kg internally and its printouts in days):
lengths km, velocities km/s, masses kg, power kW, angles deg (but ``$DATA.THCONV`` rad and
``$ERANAL.GXPNT`` mrad, as the TOML fields), **every time in days** (hence the conversions
hours <-> days for ``$ERRCON.DTNOIS``, ``$ERTRAJ.DTPDOT``, ``$ERTRAJ.DTSTM`` and
``$ERANAL.MINTVL``), **measurement sigmas in FRACAS's internal units** km, km/s or rad
(``$ERANAL.MSIGMA``, ``$GENCOV.GMSIG``; the TOML decks write m, mm/s, deg or µrad by type,
:data:`fracas.measurements.kinds.SIGMA_UNITS`), **TOM's first correction in percent**
(``$DATA.PERCEN``: "percentage of targeting error to be corrected in first iteration"; TOML
``tom.correction_fraction`` is a fraction), and **thrust-arc numbers from 1** (Fortran;
``$ERANAL.GARC``; TOML ``guidance.arc`` counts from 0).  Every conversion applied is listed in
the import's notes.

Reading uses f90nml (both ``&GROUP ... /`` and FRACAS's ``$GROUP ... $END`` forms, repeated
groups, ``NAME(k)`` and ``NAME(j,k)`` arrays, with ``global_start_index = 1`` so a partly
given array keeps its positions).  Three things are hand-parsed, because f90nml skips text
outside a group: the mode label that begins a FRACAS deck (§3: "an alphanumeric label or an
integer which will determine the program mode": ``TOM``/``1``, ``TEAM``/``2``, ``TSIM``/``3``,
``PROPAGATE``; the integers are fracas's reading), any other text outside a group (event
schedule cards: reported as not read), and a station list or name list given as one
blank-separated string (``MSTA(k) = 'GOLDSTONE MADRID'``) besides the ``MSTA(j,k)`` form.

A namelist deck may hold several modes' namelists (a TSIM deck carries the TEAM study it flies,
a TEAM deck the reference trajectory in ``$ERTRAJ``).  The TOML decks name their sub-decks by
file, so the import returns the main deck and its *companions*: ``<name>_traj.toml`` (the
trajectory of ``$ERTRAJ``) and ``<name>_team.toml`` (the TEAM study of a TSIM deck), unless
the deck names existing TOML decks itself (``$ERTRAJ.DECK``, ``$INSIM.TEAMDK``, fracas
extensions).  FRACAS has no sweep mode: a sweep deck has no namelist form.

Nothing here imports JAX.
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import f90nml
import tomli_w

from fracas.config.trajectory import MAX_DECK_BYTES, cut
from fracas.errors import DeckError
from fracas.measurements.kinds import SIGMA_UNITS

__all__ = [
    "ImportResult",
    "Unmapped",
    "import_namelist",
    "namelist_from_deck",
    "namelist_fields",
    "NAMELIST_MODES",
    "KNOWN_GROUPS",
]

#: the modes a namelist deck can be imported as (FRACAS has no sweep mode)
NAMELIST_MODES = ("propagate", "tom", "team", "tsim")
#: the namelist groups of FRACAS (report §3)
KNOWN_GROUPS = ("DATA", "SMAG", "ERRCON", "ERTRAJ", "ERANAL", "GENCOV", "INSIM", "INMAN")
_MODE_LABELS = {"TOM": "tom", "1": "tom", "TEAM": "team", "2": "team", "TSIM": "tsim", "3": "tsim"}
_MODE_LABELS["PROPAGATE"] = "propagate"
_LABEL_OF_MODE = {"tom": "TOM", "team": "TEAM", "tsim": "TSIM", "propagate": "PROPAGATE"}
#: which groups each mode reads
_MODE_GROUPS = {
    "propagate": ("DATA",),
    "tom": ("DATA", "SMAG"),
    "team": ("ERRCON", "ERTRAJ", "ERANAL", "GENCOV"),
    "tsim": ("INSIM", "INMAN", "ERRCON", "ERTRAJ", "ERANAL", "GENCOV"),
}


# --------------------------------------------------------------------------- the mapping


@dataclass(frozen=True)
class NmlField:
    """One namelist variable and the TOML field it fills.

    ``path``: the TOML path in its deck; ``"*"`` is a list index (``NAME(k)`` -> entry k-1), an
    int a component of a vector.  ``kind``: real, int, str, bool, epoch (ISO string or Julian
    date), code (integer code or the TOML string), reals / strs (a list; with ``"*"`` in the
    path, a 2-D array ``NAME(j,k)``), boolstr (logical or a string), key (the key of a TOML
    table keyed by name), msig (a measurement sigma in km, km/s or rad by the entry's type).
    ``scale``: TOML value = namelist value x scale."""

    name: str
    path: tuple
    kind: str
    doc: str
    scale: float = 1.0
    codes: tuple = ()
    unit: str = ""

    @property
    def indexed(self) -> bool:
        return "*" in self.path


def _f(name, path, kind, doc, scale=1.0, codes=(), unit=""):
    return NmlField(name, tuple(path.split(".")) if isinstance(path, str) else path, kind, doc, scale, codes, unit)


_ATT = ((1, "velocity"), (2, "inertial"), (3, "velocity_yaw_switch"))
_STOP = ((1, "time"), (2, "soi_entry"), (3, "closest_approach"), (4, "radius"))
#: $DATA / $ERTRAJ: the trajectory (a trajectory deck's fields), report §3.1 "Trajectory and
#: integration parameters", "Nominal spacecraft parameters", "Nominal thrust controls"
TRAJECTORY_FIELDS: tuple[NmlField, ...] = (
    _f("TITLE", "title", "str", "the deck's title (FRACAS: the card before the namelists)"),
    _f("EPOCH", "epoch.iso", "str", "initial epoch, ISO calendar date (TDB)"),
    _f("JD0", "epoch.julian_date", "real", "initial epoch, Julian date (TDB)", unit="d"),
    _f("CENTRE", "initial_state.centre", "str", "launch planet: the primary body of the initial state"),
    _f("FRAME", "initial_state.frame", "str", "axes of the initial state: EME2000, ECLIPJ2000, BODY_EQUATOR"),
    _f("ICOORD", ("initial_state", "@kind"), "int", "flag indicating the coordinate system of X0 (see X0)"),
    _f(
        "X0",
        ("initial_state", "@x0"),
        "reals",
        "initial state: ICOORD 1 x,y,z,vx,vy,vz (km, km/s); 2 (mean "
        "anomaly) / 3 (true anomaly) a,e,i,raan,argp,anomaly (km, deg); 4 r,lat,lon,v,gamma,sigma (km, deg, km/s)",
    ),
    _f("MASS0", "spacecraft.mass_kg", "real", "initial mass", unit="kg"),
    _f("AREA", "spacecraft.area_m2", "real", "solar radiation pressure area", unit="m2"),
    _f("CR", "spacecraft.cr", "real", "reflectivity coefficient"),
    _f(
        "IPOWER",
        "propulsion.power_source",
        "code",
        "flag indicating power source",
        codes=((1, "solar"), (2, "nuclear")),
    ),
    _f("POWER0", "propulsion.power_kw", "real", "base power (at 1 AU if solar)", unit="kW"),
    _f("TDECAY", "propulsion.decay_days", "real", "nuclear power decay time", unit="d"),
    _f("ETA", "propulsion.efficiency", "real", "thruster efficiency"),
    _f("CEXH", "propulsion.exhaust_velocity_km_s", "real", "exhaust velocity", unit="km/s"),
    _f("ISP", "propulsion.isp_s", "real", "specific impulse (instead of CEXH)", unit="s"),
    _f("TSCALE", "propulsion.thrust_scale", "real", "thrust proportionality factor"),
    _f("TON", "thrust_arc.*.start_days", "real", "thrust arc k on (control array)", unit="d"),
    _f("TOFF", "thrust_arc.*.stop_days", "real", "thrust arc k off", unit="d"),
    _f("IATT", "thrust_arc.*.frame", "code", "attitude mode of arc k", codes=_ATT),
    _f("ALPHA", "thrust_arc.*.alpha_deg", "real", "in-plane pointing angle (or right ascension)", unit="deg"),
    _f("BETA", "thrust_arc.*.beta_deg", "real", "out-of-plane pointing angle (or declination)", unit="deg"),
    _f("THROT", "thrust_arc.*.throttle", "real", "thrust level of arc k (0-1)"),
    _f("TIMP", "impulse.*.time_days", "real", "impulse k time", unit="d"),
    _f("DVX", ("impulse", "*", "dv_km_s", 0), "real", "impulse k, first component", unit="km/s"),
    _f("DVY", ("impulse", "*", "dv_km_s", 1), "real", "impulse k, second component", unit="km/s"),
    _f("DVZ", ("impulse", "*", "dv_km_s", 2), "real", "impulse k, third component", unit="km/s"),
    _f("IMPFRM", "impulse.*.frame", "code", "impulse k axes", codes=((1, "velocity"), (2, "inertial"))),
    _f("ISPIMP", "impulse.*.isp_s", "real", "impulsive engine specific impulse", unit="s"),
    _f("BODIES", "forces.third_bodies", "strs", "intermediate gravitational bodies"),
    _f("LJ2", "forces.j2", "bool", "central-body J2"),
    _f("LSRP", "forces.srp", "bool", "solar radiation pressure"),
    _f("LSOI", "forces.change_primary_at_soi", "bool", "change the primary at sphere-of-influence crossings"),
    _f("OVBODY", "forces.overrides.*", "key", "body k whose constants are overridden"),
    _f("OVMU", "forces.overrides.*.mu_km3_s2", "real", "GM of OVBODY(k)", unit="km3/s2"),
    _f("OVJ2", "forces.overrides.*.j2", "real", "J2 of OVBODY(k)"),
    _f("OVRAD", "forces.overrides.*.radius_km", "real", "radius of OVBODY(k)", unit="km"),
    _f("CBODY", "forces.conic_bodies.*", "key", "body k with a conic ephemeris (target ephemeris if not internal)"),
    _f("CA", "forces.conic_bodies.*.a_km", "real", "conic semi-major axis", unit="km"),
    _f("CE", "forces.conic_bodies.*.e", "real", "conic eccentricity"),
    _f("CI", "forces.conic_bodies.*.i_deg", "real", "conic inclination", unit="deg"),
    _f("CRAAN", "forces.conic_bodies.*.raan_deg", "real", "conic node", unit="deg"),
    _f("CARGP", "forces.conic_bodies.*.argp_deg", "real", "conic argument of periapsis", unit="deg"),
    _f("CMANOM", "forces.conic_bodies.*.mean_anomaly_deg", "real", "conic mean anomaly", unit="deg"),
    _f("CEPOCH", "forces.conic_bodies.*.epoch", "epoch", "conic epoch (ISO string or Julian date, TDB)"),
    _f("CFRAME", "forces.conic_bodies.*.frame", "str", "axes of the conic angles"),
    _f("METHOD", "integrator.method", "str", "integrator: auto, dprkn12, dprkn8, dop853, rkn4 (FRACAS's Nystrom)"),
    _f("FORMUL", "integrator.formulation", "str", "auto, cowell, encke"),
    _f("STEPC", "integrator.step_control", "str", "auto, tolerance, c_nom"),
    _f("TOL", "integrator.tolerance", "real", "integration accuracy level: relative local error"),
    _f("ACCLEV", "integrator.c_nom", "real", "integration accuracy level of the Nystrom step rule (c_nom)"),
    _f("DTMAX", "integrator.dt_max_s", "real", "largest step", unit="s"),
    _f("RECT", "integrator.rect_ratio", "real", "Encke rectification ratio"),
    _f("EPST", "integrator.eps_t_s", "real", "event time tolerance", unit="s"),
    _f("MAXSTP", "integrator.max_steps", "int", "most steps"),
    _f("TFINAL", "stop.duration_days", "real", "total flight time", unit="d"),
    _f("EPOCHF", "stop.final_epoch", "epoch", "final date (ISO string or Julian date, TDB)"),
    _f("ISTOP", "stop.condition", "code", "trajectory stopping condition", codes=_STOP),
    _f("STBODY", "stop.body", "str", "target planet of the stopping condition"),
    _f("RSTOP", "stop.radius_km", "real", "radius of designated final orbit", unit="km"),
    _f("TOUT", "output.times_days", "reals", "output times", unit="d"),
    _f("DTOUT", "output.step_days", "real", "output step", unit="d"),
    _f("LOUTF", "output.include_final", "bool", "output the final state"),
    _f("SENS", "output.sensitivities", "strs", "parameter labels whose sensitivities are output"),
    _f("LSTMO", "output.stm", "bool", "output the transition matrices"),
    _f("MXOUT", "limits.max_output_times", "int", "most output times"),
    _f("MXSCHD", "limits.max_schedule_times", "int", "most schedule times"),
    _f("MXMEAS", "limits.max_measurements", "int", "most measurements"),
    _f("MXSTMT", "limits.max_stm_times", "int", "most STM file times"),
    _f("MXEVNT", "limits.max_events", "int", "most events"),
)

_SUBMODES = ((0, "auto"), (1, "grid"), (2, "target"), (3, "target_optimize"), (4, "optimize"), (5, "nominal"))
#: $DATA: TOM's iteration inputs, control codes and targets (report §3.1; digest §A.2)
TOM_FIELDS: tuple[NmlField, ...] = (
    _f(
        "ISUBM",
        "tom.submode",
        "code",
        "submode: 0 auto (TEST), 1 grid, 2 targeting, 3 both, 4 optimization, 5 nominal only",
        codes=_SUBMODES,
    ),
    _f("OPTIM", "tom.optimizer", "str", "projected_gradient, slsqp, trust_constr"),
    _f("SENSM", "tom.sensitivities", "str", "ad or fegs (finite differences)"),
    _f("MAXIT", "tom.max_iterations", "int", "maximum number of iterations"),
    _f("DFMAX", "tom.max_performance_change_kg", "real", "maximum change in performance in one iteration", unit="kg"),
    _f(
        "PERCEN",
        "tom.correction_fraction",
        "real",
        "percentage of targeting error corrected in the first iteration (percent; TOML: fraction)",
        scale=0.01,
        unit="%",
    ),
    _f("RLIN", "tom.linearity_radius", "real", "estimated radius of linearity region in control space"),
    _f("GAMMAX", "tom.max_scale_factor", "real", "maximum value of control change scale factor"),
    _f("ETAFIT", "tom.curve_fit_tolerance", "real", "curve fitting tolerance for trial trajectories"),
    _f("THMIN", "tom.dependent_angle_deg", "real", "minimum angle between control vector elements", unit="deg"),
    _f("THCONV", "tom.convergence_angle_rad", "real", "TEST's convergence angle", unit="rad"),
    _f("TUP", "tom.targeting_threshold", "real", "normalized targeting error below which targeting only stops"),
    _f("TLOW", "tom.optimization_threshold", "real", "normalized targeting error below which optimization only"),
    _f(
        "IWGHT",
        "tom.weighting",
        "code",
        "weighting: 1 sensitivity, 2 control",
        codes=((1, "sensitivity"), (2, "control")),
    ),
    _f("DEPBOD", "tom.departure_body", "str", "departure body of the v-infinity controls"),
    _f("RESULT", "tom.results", "str", "results file (fracas)"),
    _f("REFDK", "tom.reference_deck", "str", "reference trajectory deck written (fracas)"),
    _f("PLOT", "tom.plot", "str", "plot file (fracas)"),
    _f("STMFIL", "tom.stm_file", "str", "STM file of the optimum (fracas)"),
    _f("UNAME", "control.*.name", "str", "control parameter code k (a fracas control name)"),
    _f("UNOM", "control.*.nominal", "real", "nominal value of control k (deck units)"),
    _f("USCALE", "control.*.scale", "real", "control parameter weighting k_j"),
    _f("ULOW", "control.*.lower", "real", "lower bound of control k"),
    _f("UUPP", "control.*.upper", "real", "upper bound of control k"),
    _f("DELU", "control.*.fd_step", "real", "control parameter perturbation"),
    _f("ULINK", ("control", "*", "links", "@name"), "strs", "controls linked to control k (ULINK(j,k))"),
    _f("ULCOEF", ("control", "*", "links", "@value"), "reals", "coefficients of the linked controls (ULCOEF(j,k))"),
    _f("TNAME", "target.*.name", "str", "target parameter k (a fracas target name)"),
    _f("TVAL", "target.*.value", "real", "desired target value (deck units)"),
    _f("TTOL", "target.*.tolerance", "real", "target tolerance"),
    _f("TBODY", "target.*.body", "str", "body of target k"),
    _f("GRINC", "grid.increments", "reals", "grid increments, one per control"),
    _f("GRSTEP", "grid.steps", "int", "grid steps each side"),
    _f("LGPAIR", "grid.pairs", "bool", "grid pairs of controls"),
)
#: $SMAG: targeting sensitivities and performance gradient (report §3.1)
SMAG_FIELDS: tuple[NmlField, ...] = (
    _f("S", ("smag", "@s"), "reals", "targeting sensitivities S(i,j): target i, control j (deck units)"),
    _f("G", "smag.g", "reals", "performance gradient G(j)"),
)
#: $ERRCON: what the run does (report §3.2)
ERRCON_FIELDS: tuple[NmlField, ...] = (
    _f("LSTM", "errcon.build_stm", "boolstr", "STM file creation: T, F or 'IF_MISSING'"),
    _f("LANAL", "errcon.analysis", "bool", "error analysis execution"),
    _f(
        "LCOVIN",
        ("errcon", "@propagation"),
        "bool",
        "integration of covariance variational equations (T: pdot, F: transition matrices, phi)",
    ),
    _f("STMFIL", "errcon.stm_file", "str", "the STM file"),
    _f("NOISEM", "errcon.process_noise", "str", "PHI mode's thrust-noise model: grid or interval"),
    _f("DTNOIS", "errcon.noise_step_hours", "real", "noise cell step (days; TOML: hours)", scale=24.0, unit="d"),
    _f("GMODEL", "errcon.guidance_model", "str", "report, orthogonal or tsim"),
    _f("GRESET", "errcon.guidance_reset", "str", "state or all"),
    _f("GESTIM", "errcon.guidance_estimates", "str", "state or state_and_solve_for"),
)
#: $ERTRAJ (besides the trajectory fields): report §3.2
ERTRAJ_FIELDS: tuple[NmlField, ...] = (
    _f("DECK", "ertraj.deck", "str", "an existing TOML trajectory deck instead of inline fields (fracas)"),
    _f("DTPDOT", "ertraj.pdot_step_hours", "real", "PDOT integration step (days; TOML: hours)", scale=24.0, unit="d"),
    _f("STMPAR", "stm.parameters", "strs", "parameter list for state transition matrices"),
    _f("DTSTM", "stm.grid_hours", "real", "uniform grid of STM file times (days; TOML: hours)", scale=24.0, unit="d"),
)


def _apriori(prefix: str, path: str, what: str) -> tuple[NmlField, ...]:
    return (
        _f(prefix + "PSIG", path + ".position_sigma_km", "reals", what + " position sigmas (3)", unit="km"),
        _f(prefix + "PRSS", path + ".position_rss_km", "real", what + " position RSS", unit="km"),
        _f(prefix + "VSIG", path + ".velocity_sigma_km_s", "reals", what + " velocity sigmas (3)", unit="km/s"),
        _f(prefix + "VRSS", path + ".velocity_rss_km_s", "real", what + " velocity RSS", unit="km/s"),
        _f(prefix + "MSIG", path + ".mass_sigma_kg", "real", what + " mass sigma", unit="kg"),
        _f(prefix + "PUNCH", path + ".from_punch", "str", what + " covariance from a punch file"),
    )


def _noise(path: str) -> tuple[NmlField, ...]:
    out = []
    for suffix, comp, unit in (
        ("P", "proportionality", ""),
        ("A", "in_plane_deg", "deg"),
        ("B", "out_of_plane_deg", "deg"),
    ):
        out.append(_f("TNSIG" + suffix, f"{path}.{comp}.sigma", "real", f"thrust noise sigma, {comp}", unit=unit))
        out.append(
            _f("TNTAU" + suffix, f"{path}.{comp}.tau_days", "real", f"thrust noise correlation time, {comp}", unit="d")
        )
    return tuple(out)


_ROLES = ((1, "solve_for"), (2, "consider"), (3, "ignore"))
#: $ERANAL: the error analysis (report §3.2)
ERANAL_FIELDS: tuple[NmlField, ...] = (
    _f(
        "IFILT",
        "filter.type",
        "code",
        "filtering algorithm flag: 1 K-S, 2 WLS, 3 user",
        codes=((1, "kalman_schmidt"), (2, "wls"), (3, "user")),
    ),
    _f("USRGAN", "filter.user_gain", "str", "the user gain (module:function)"),
    _f("LSQRT", "filter.square_root", "bool", "square-root filter"),
    _f("ELMIN", "filter.min_elevation_deg", "real", "minimum elevation", unit="deg"),
    _f("TSTART", "filter.start_days", "real", "start of the study", unit="d"),
    _f("TSTOP", "filter.stop_days", "real", "end of the study", unit="d"),
    *_apriori("K", "a_priori", "knowledge (a priori)"),
    *_apriori("C", "control", "control (injection dispersion)"),
    _f("PLABEL", "parameter.*.label", "str", "parameter k (a fracas parameter label)"),
    _f("PSIGMA", "parameter.*.sigma", "real", "a priori sigma of parameter k (the label's unit)"),
    _f("PROLE", "parameter.*.role", "code", "list of parameter k: 1 solve-for, 2 consider, 3 ignore", codes=_ROLES),
    *_noise("thrust_noise"),
    _f("STNAME", "station.*.name", "str", "station k (added or overriding a standard one)"),
    _f("STRAD", "station.*.radius_km", "real", "station k radius", unit="km"),
    _f("STLAT", "station.*.latitude_deg", "real", "station k latitude", unit="deg"),
    _f("STLON", "station.*.longitude_deg", "real", "station k longitude", unit="deg"),
    _f("MTYPE", "tracking.*.type", "str", "measurement schedule k: data type"),
    _f("MSTA", "tracking.*.stations", "strs", "stations of schedule k (MSTA(j,k))"),
    _f("MSTART", "tracking.*.start_days", "real", "schedule k start", unit="d"),
    _f("MSTOP", "tracking.*.stop_days", "real", "schedule k stop", unit="d"),
    _f("MINTVL", "tracking.*.interval_hours", "real", "schedule k interval (days; TOML: hours)", scale=24.0, unit="d"),
    _f("MSIGMA", "tracking.*.sigma", "msig", "measurement noise of schedule k (km, km/s or rad by type)"),
    _f("MBODY", "tracking.*.body", "str", "observed body of schedule k"),
    _f("MSTRA", "tracking.*.star_ra_deg", "real", "star right ascension", unit="deg"),
    _f("MSTDEC", "tracking.*.star_dec_deg", "real", "star declination", unit="deg"),
    _f("ETYPE", "event.*.type", "str", "event k: eigenvector, propagation or prediction"),
    _f("ETIMES", "event.*.times_days", "reals", "event k times (ETIMES(j,k))", unit="d"),
    _f("ESTART", "event.*.start_days", "real", "event k first time", unit="d"),
    _f("ESTOP", "event.*.stop_days", "real", "event k last time", unit="d"),
    _f("EDT", "event.*.interval_days", "real", "event k interval", unit="d"),
    _f("EPRED", "event.*.predict_to_days", "real", "prediction event k: predicted to", unit="d"),
    _f("IPREVN", "print.every", "int", "print measurements according to number (every n-th)"),
    _f("LPCORR", "print.correlations", "bool", "print correlations"),
    _f("LPNOIS", "print.process_noise", "bool", "propagation event print (process noise)"),
    _f("PUTIME", "punch.times_days", "reals", "knowledge and control punched at these times", unit="d"),
    _f("PUFILE", "punch.file", "str", "the punch file"),
    _f("LGENCV", "gencov.enabled", "bool", "generalized covariance flag"),
    _f("GNAME", "guidance.*.name", "str", "guidance event k name"),
    _f("GTYPE", "guidance.*.type", "str", "guidance event k: impulsive, primary, vernier, none"),
    _f("GTIME", "guidance.*.time_days", "real", "guidance event k time", unit="d"),
    _f("GTARG", "guidance.*.targets", "strs", "target set of event k (GTARG(j,k))"),
    _f("GTTIME", "guidance.*.target_time_days", "real", "target time of event k", unit="d"),
    _f("GTBODY", "guidance.*.target_body", "str", "target body of event k"),
    _f("GARC", ("guidance", "*", "@arc"), "int", "thrust arc corrected by event k (from 1; TOML arc from 0)"),
    _f("GCTRL", "guidance.*.controls", "strs", "controls of event k (GCTRL(j,k))"),
    _f("GWGHT", "guidance.*.weights", "reals", "control weighting factors of event k (GWGHT(j,k))"),
    _f("GTOL", "guidance.*.tolerances", "reals", "target tolerances of event k (GTOL(j,k))"),
    _f("GXPROP", "guidance.*.execution.proportionality", "real", "execution error: proportionality"),
    _f("GXPNT", "guidance.*.execution.pointing_mrad", "real", "execution error: pointing", unit="mrad"),
    _f("GXRES", "guidance.*.execution.resolution_m_s", "real", "execution error: resolution", unit="m/s"),
    _f("LBUDG", "budget.enabled", "bool", "error budget"),
    _f("BUDGT", "budget.at_days", "reals", "error budget epochs", unit="d"),
    _f("RESULT", "output.results", "str", "results file (fracas)"),
    _f("PLOT", "output.plot", "str", "plot file (fracas)"),
    _f("TITLE", "title", "str", "the study's title"),
    *(_f(x.name, x.path, x.kind, x.doc) for x in TRAJECTORY_FIELDS if x.path[0] == "limits"),
)
#: $GENCOV: what the real world does differently (report §3.2)
GENCOV_FIELDS: tuple[NmlField, ...] = (
    *_apriori("T", "gencov.a_priori", "true a priori"),
    _f("IGLAB", "gencov.parameter.*.label", "str", "parameter k whose true sigma differs, or an ignore parameter"),
    _f("IGSIG", "gencov.parameter.*.sigma", "real", "true sigma of parameter k"),
    _f("IGROLE", "gencov.parameter.*.role", "str", "'IGNORE' for an ignore parameter"),
    *_noise("gencov.thrust_noise"),
    _f("GMTYPE", "gencov.measurement_sigma.*", "key", "data type k whose true noise differs"),
    _f("GMSIG", ("gencov", "measurement_sigma", "*", "@value"), "msig", "true noise of GMTYPE(k) (km, km/s, rad)"),
)
#: $INSIM: the Monte Carlo (report §3.3)
INSIM_FIELDS: tuple[NmlField, ...] = (
    _f("TEAMDK", "insim.team_deck", "str", "an existing TOML TEAM deck instead of the TEAM namelists (fracas)"),
    _f("NMISS", "insim.missions", "int", "maximum number of mission cycles"),
    _f("MFIRST", "insim.first_mission", "int", "index of the first mission (fracas)"),
    _f("ISEED", "insim.seed", "int", "random number initializer"),
    _f("NBATCH", "insim.batch_missions", "int", "missions per task (fracas)"),
    _f("SCALE", "insim.scale", "real", "every dispersion x SCALE"),
    _f(
        "ISAMP",
        "insim.sampling",
        "code",
        "sampling: 1 eigen (CSAMP), 2 cholesky",
        codes=((1, "eigen"), (2, "cholesky")),
    ),
    _f("DTNOIS", "insim.noise_step_days", "real", "Gauss-Markov hold step", unit="d"),
    _f("CLOSE", "insim.near_success_factor", "real", "GUIDS near-success factor"),
    _f("IMPPRO", "insim.impulse_propellant", "str", "spent or booked"),
    _f("APSTAT", "insim.a_priori_statistics", "strs", "cumulative a priori error statistics (previous runs' files)"),
    _f("TCFLD", "insim.team_changes.*", "key", "TEAM-deck field k changed for this run (a field path)"),
    _f("TCVAL", ("insim", "team_changes", "*", "@value"), "any", "the value of TEAM-deck field TCFLD(k)"),
    _f("IJFRM", "insim.injection.frame", "str", "injection dispersion axes: inertial or rtn"),
    _f("IJPSIG", "insim.injection.position_sigma_km", "reals", "state error: position sigmas (3)", unit="km"),
    _f("IJVSIG", "insim.injection.velocity_sigma_km_s", "reals", "state error: velocity sigmas (3)", unit="km/s"),
    _f("IJMSIG", "insim.injection.mass_sigma_kg", "real", "initial mass sigma", unit="kg"),
    _f("RESULT", "output.results", "str", "results file (fracas)"),
    _f("PLOT", "output.plot", "str", "plot file (fracas)"),
    _f("TITLE", "title", "str", "the run's title"),
)
#: $INMAN: one maneuver (report §3.3); path relative to its [[maneuver]] entry
INMAN_FIELDS: tuple[NmlField, ...] = (
    _f("NAME", "name", "str", "the TEAM guidance event it flies"),
    _f("LAW", "law", "code", "guidance law: 1 linear, 2 non-linear", codes=((1, "linear"), (2, "nonlinear"))),
    _f("MAXIT", "max_iterations", "int", "non-linear guidance iterations"),
    _f("TOL", "tolerance", "reals", "target tolerances (target units)"),
    _f("KNOW", "knowledge", "str", "estimation error covariance from 'team' or 'deck'"),
    _f("KPSIG", "knowledge_position_sigma_km", "reals", "estimation error position sigmas (3)", unit="km"),
    _f("KVSIG", "knowledge_velocity_sigma_km_s", "reals", "estimation error velocity sigmas (3)", unit="km/s"),
    _f("ENABLE", "enabled", "bool", "the event is flown"),
)

#: FRACAS inputs of the report with no fracas equivalent: (group, name) -> why
KNOWN_UNMAPPED: dict[tuple[str, str], str] = {
    ("ERANAL", "IPRINT"): "no equivalent (print control)",
    ("ERANAL", "IPTIME"): "no equivalent (print measurements according to time)",
    ("ERANAL", "IPTYPE"): "no equivalent (print measurements according to type)",
    ("ERANAL", "IPUNCH"): "no equivalent (punch flags: [punch] times_days and file)",
    ("ERANAL", "NMEAS"): "no equivalent (number of schedule cards: the array lengths)",
    ("ERANAL", "NPROP"): "no equivalent (number of propagation event cards: the array lengths)",
    ("ERANAL", "NEIG"): "no equivalent (number of eigenvector events: the array lengths)",
    ("ERANAL", "NPRED"): "no equivalent (number of prediction events: the array lengths)",
    ("ERANAL", "NGUID"): "no equivalent (number of guidance events: the array lengths)",
    ("ERANAL", "LPGVM"): "no equivalent (punch guidance variation matrices: recomputed each run)",
    ("ERTRAJ", "XEPHEM"): "no equivalent (tabulated target ephemeris: give CBODY conic elements)",
    ("ERRCON", "IPRINT"): "no equivalent (print control)",
    ("DATA", "IPRINT"): "no equivalent (print control: the report has one level)",
    ("DATA", "NCTRL"): "no equivalent (number of control parameters: the array lengths)",
    ("DATA", "NTARG"): "no equivalent (number of target conditions: the array lengths)",
    ("INSIM", "IPRINT"): "no equivalent (print control)",
    ("INSIM", "IPUNCH"): "no equivalent (punch flags: the results file carries the statistics)",
    ("INSIM", "NMAN"): "no equivalent (number of maneuvers: one $INMAN each)",
    ("INSIM", "NAPRI"): "no equivalent (a priori cycle count: read from the APSTAT files)",
    ("INMAN", "NAPRI"): "no equivalent (a priori cycle count: read from the APSTAT files)",
    ("INMAN", "SMAT"): "no equivalent (target sensitivity or guidance matrix: always computed)",
}


def _table(group: str, mode: str) -> tuple[NmlField, ...]:
    """The fields a group holds in a mode."""
    if group == "DATA":
        return TRAJECTORY_FIELDS + (TOM_FIELDS if mode == "tom" else ())
    if group == "ERTRAJ":
        return ERTRAJ_FIELDS + TRAJECTORY_FIELDS
    return {
        "SMAG": SMAG_FIELDS,
        "ERRCON": ERRCON_FIELDS,
        "ERANAL": ERANAL_FIELDS,
        "GENCOV": GENCOV_FIELDS,
        "INSIM": INSIM_FIELDS,
        "INMAN": INMAN_FIELDS,
    }[group]


def namelist_fields() -> dict[str, tuple[NmlField, ...]]:
    """Every group's fields (for the documentation table)."""
    return {
        "DATA (trajectory)": TRAJECTORY_FIELDS,
        "DATA (TOM)": TOM_FIELDS,
        "SMAG": SMAG_FIELDS,
        "ERRCON": ERRCON_FIELDS,
        "ERTRAJ": ERTRAJ_FIELDS,
        "ERANAL": ERANAL_FIELDS,
        "GENCOV": GENCOV_FIELDS,
        "INSIM": INSIM_FIELDS,
        "INMAN": INMAN_FIELDS,
    }


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Unmapped:
    """A namelist field the import could not map: ``$NAMELIST.NAME = value: reason``."""

    namelist: str
    name: str
    value: Any
    reason: str

    def __str__(self) -> str:
        if self.namelist == "-":  # text outside any group
            return f"{self.name}: {cut(_show(self.value), 40)}: {self.reason}"
        return f"${self.namelist}.{self.name} = {cut(_show(self.value), 40)}: {self.reason}"


@dataclass
class ImportResult:
    """The TOML deck written from a namelist deck.

    ``toml``: the main deck's text; ``mode``: its mode; ``companions``: file name (relative to
    the main deck) -> TOML text of a sub-deck it names; ``unmapped``: every field not mapped;
    ``notes``: conversions applied and defaults assumed; ``mapped``: how many fields mapped;
    ``decks``: part ("traj", "team", "tom", "tsim") -> the TOML data written for it."""

    toml: str
    mode: str
    companions: dict[str, str] = field(default_factory=dict)
    unmapped: list[Unmapped] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    mapped: int = 0
    decks: dict[str, dict] = field(default_factory=dict)


def _show(v: Any) -> str:
    if isinstance(v, bool):
        return ".TRUE." if v else ".FALSE."
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, list):
        return ", ".join(_show(x) for x in v)
    if isinstance(v, dict):
        return "{" + ", ".join(v) + "}"
    return str(v)


# --------------------------------------------------------------------------- reading

_GROUP_START = re.compile(r"^\s*[&$]([A-Za-z][A-Za-z0-9_]*)")
_GROUP_END = re.compile(r"(/|[&$]END\b|\$)\s*$", re.IGNORECASE)
_STRINGS = re.compile(r"'(?:[^']|'')*'|\"(?:[^\"]|\"\")*\"")


def _scan_outside(text: str) -> tuple[str | None, list[tuple[int, str]]]:
    """Hand scan of what f90nml skips: (the mode label, [(line number, text outside any group)])."""
    label, outside, inside = None, [], False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = _STRINGS.sub("''", raw).split("!")[0]
        if not line.strip():
            continue
        if not inside:
            m = _GROUP_START.match(line)
            if m is None:
                word = line.strip().upper()
                if label is None and not outside and word in _MODE_LABELS:
                    label = word
                else:
                    outside.append((number, raw.strip()))
                continue
            inside = True
            line = line[m.end() :]
            if m.group(1).upper() == "END":
                inside = False
                continue
        if _GROUP_END.search(line) or re.search(r"[&$]END\b", line, re.IGNORECASE):
            inside = False
    return label, outside


def _read_text(text_or_path: str | Path, source: str | None) -> tuple[str, str]:
    """(text, source) of a namelist deck given as text or as a path."""
    if isinstance(text_or_path, Path) or (
        isinstance(text_or_path, str) and "\n" not in text_or_path and not re.search(r"[&$=]", text_or_path)
    ):
        p = Path(text_or_path)
        src = source or str(p)
        try:
            raw = p.read_bytes()
        except FileNotFoundError:
            raise DeckError(f"{src}: no such file") from None
        except IsADirectoryError:
            raise DeckError(f"{src}: is a directory, expected a FRACAS namelist deck") from None
        except OSError as exc:
            raise DeckError(f"{src}: cannot read: {exc.strerror or exc}") from None
        if len(raw) > MAX_DECK_BYTES:
            raise DeckError(f"{src}: is {len(raw)} bytes; a deck is at most {MAX_DECK_BYTES} bytes")
        try:
            return raw.decode("utf-8"), src
        except UnicodeDecodeError:
            return raw.decode("latin-1"), src  # old decks: any 8-bit text
    return str(text_or_path), source or "<namelist>"


def _dropped_value(message: str) -> str:
    """The problem behind f90nml's "Value X is not assigned to any variable" warning: more
    values than the indices written take (``IATT(2) = 2, 2``: f90nml keeps the first only),
    naming the variable as written when the parser's frame shows it."""
    import sys

    m = re.search(r"Value (.*) is not assigned to any variable", message)
    value = m.group(1) if m else "?"
    name, group, bounds = None, None, None
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "_parse_variable" and name is None:
            name = frame.f_locals.get("v_name")
            bounds = frame.f_locals.get("v_idx_bounds")
        if "g_name" in frame.f_locals and group is None:
            group = frame.f_locals.get("g_name")
        frame = frame.f_back
    if name is None:
        return f"value {cut(value, 40)} is not assigned to any variable: expected one value per index written"
    where = f"${str(group or '?').upper()}.{str(name).upper()}"
    if bounds:
        where += "(" + ",".join(_bound_text(b) for b in bounds) + ")"
        low = [b[0] for b in bounds if isinstance(b, (tuple, list)) and b and b[0] is not None]
        if low and min(low) < 1:
            return f"{where}: index {min(low)}: {_BELOW_ONE}"
    return (
        f"{where} = ..., {cut(value, 40)}: more values than the indices written (the extra ones would be "
        f"dropped); expected one value per index, or a range {str(name).upper()}(k:m) = ..."
    )


_BELOW_ONE = "expected indices from 1 (FRACAS arrays start at 1; nothing below 1 is read)"


def _bound_text(b: Any) -> str:
    try:
        lo, hi, step = b
    except (TypeError, ValueError):
        return str(b)
    if hi is None or (lo is not None and hi == lo + 1 and step in (None, 1)):
        return str(lo)
    return f"{'' if lo is None else lo}:{hi - 1}" + ("" if step in (None, 1) else f":{step}")


def _parse(text: str, src: str) -> list[tuple[str, int, dict]]:
    """[(GROUP, occurrence, {NAME: value})] in deck order, by f90nml."""
    parser = f90nml.Parser()
    parser.global_start_index = 1
    dropped: list[str] = []
    try:
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():  # the tokenizer prints
            warnings.showwarning = lambda message, *_a, **_k: dropped.append(_dropped_value(str(message)))
            warnings.simplefilter("always")
            nml = parser.reads(text)
    except Exception as exc:  # f90nml raises ValueError, AssertionError, IndexError ... on bad text
        why = str(exc).strip() or type(exc).__name__
        raise DeckError(
            f"{src}: not a readable namelist deck ({cut(why, 80)}); expected &GROUP ... / or $GROUP ... $END"
        ) from None
    if dropped:
        raise DeckError(f"{src}: {dropped[0]}")
    out = []
    seen: dict[str, int] = {}
    for name, body in nml.items():  # a repeated group comes once per occurrence (or as a list)
        for b in body if isinstance(body, list) else [body]:
            group = name.upper()
            for var, first in getattr(b, "start_index", {}).items():
                if any(i is not None and i < 1 for i in first):
                    idx = ",".join("1" if i is None else str(i) for i in first)
                    low = min(i for i in first if i is not None)
                    raise DeckError(f"{src}: ${group}.{var.upper()}({idx}): index {low}: {_BELOW_ONE}")
            occ = seen.get(group, 0)
            seen[group] = occ + 1
            out.append((group, occ, {k.upper(): v for k, v in b.items()}))
    if not out:
        raise DeckError(f"{src}: no namelist groups found; expected &GROUP ... / or $GROUP ... $END (e.g. $DATA)")
    return out


_NUM = (int, float)
#: string fields written as given (names, files, dates); the others are matched without regard to case
_KEEP_CASE = {"TITLE", "EPOCH", "DECK", "STMFIL", "RESULT", "PLOT", "REFDK", "PUFILE", "KPUNCH", "CPUNCH", "TPUNCH"}
_KEEP_CASE |= {"APSTAT", "TEAMDK", "GNAME", "NAME", "USRGAN", "CEPOCH", "EPOCHF", "TCFLD"}


def _choices(name: str) -> tuple[str, ...] | None:
    from fracas.guidance.target_kinds import TARGET_KINDS

    if name in ("FRAME", "CFRAME"):
        return ("EME2000", "ECLIPJ2000", "BODY_EQUATOR")
    if name in ("TNAME", "GTARG"):
        return tuple(TARGET_KINDS)
    return None


def _case(name: str, v: str) -> str:
    """A string value as the TOML schema spells it: enumerations matched without regard to case
    (FRACAS decks are upper case), names and file names as given."""
    if name in _KEEP_CASE:
        return v
    choices = _choices(name)
    if choices is not None:
        for c in choices:
            if c.lower() == v.lower():
                return c
        return v
    return v.lower()


def _where(src: str, group: str, name: str, k: int | None = None, j: int | None = None) -> str:
    idx = "" if k is None else (f"({k})" if j is None else f"({j},{k})")
    return f"{src}: ${group}.{name}{idx}"


def _scalar(f: NmlField, v: Any, where: str) -> Any:
    """One namelist value -> its TOML value (type checked, converted); DeckError naming the field."""
    kind = f.kind
    if kind in ("reals",):
        kind = "real"
    if kind == "strs":
        kind = "str"
    bad = None
    if kind in ("real", "msig"):
        if isinstance(v, bool) or not isinstance(v, _NUM) or not math.isfinite(float(v)):
            bad = "a number"
        else:
            return float(v) * f.scale if f.scale != 1.0 else float(v)
    elif kind == "int":
        if isinstance(v, bool) or not isinstance(v, int):
            bad = "an integer"
        else:
            return v
    elif kind in ("str", "key"):
        if not isinstance(v, str):
            bad = "a quoted string"
        else:
            return _case(f.name, v.strip())
    elif kind == "bool":
        if not isinstance(v, bool):
            bad = "a logical (T or F)"
        else:
            return v
    elif kind == "boolstr":
        if isinstance(v, bool):
            return v
        if isinstance(v, str) and v.strip().lower() == "if_missing":
            return "if_missing"
        bad = "a logical (T or F) or 'IF_MISSING'"
    elif kind == "any":
        if isinstance(v, (bool, int, float, str)):
            return v.strip() if isinstance(v, str) else v
        bad = "a number, logical or string"
    elif kind == "epoch":
        if isinstance(v, str):
            return v.strip()
        if isinstance(v, _NUM) and not isinstance(v, bool):
            return float(v)
        bad = "an ISO date string or a Julian date"
    elif kind == "code":
        names = dict(f.codes)
        if isinstance(v, int) and not isinstance(v, bool) and v in names:
            return names[v]
        if isinstance(v, str) and v.strip().lower() in names.values():
            return v.strip().lower()
        bad = "one of " + ", ".join(f"{c} ({n})" for c, n in f.codes)
    if bad is None:
        bad = "a value"
    raise DeckError(f"{where} = {cut(_show(v), 40)}: expected {bad}")


def _set(root: dict, path: tuple, value: Any) -> None:
    """Set ``value`` at ``path`` (str keys, int list indices) creating dicts and lists."""
    cur: Any = root
    for i, part in enumerate(path):
        last = i == len(path) - 1
        nxt: Any = None if last else ([] if isinstance(path[i + 1], int) else {})
        if isinstance(part, int):
            while len(cur) <= part:
                cur.append(None if last else type(nxt)())
            if last:
                cur[part] = value
            else:
                if cur[part] is None:
                    cur[part] = nxt
                cur = cur[part]
        else:
            if last:
                cur[part] = value
            else:
                cur = cur.setdefault(part, nxt)


def _as_list(v: Any) -> list:
    return v if isinstance(v, list) else [v]


def _trim(v: list) -> list:
    while v and v[-1] is None:
        v = v[:-1]
    return v


@dataclass
class _Target:
    """Where a mode's groups write: part name -> TOML data, and provenance for error lines."""

    parts: dict[str, dict] = field(default_factory=dict)
    origin: dict[tuple[str, str], str] = field(default_factory=dict)  # (part, toml path text) -> $GROUP.NAME(k)
    mapped: int = 0


def _loc_text(path: tuple) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (("." if out else "") + str(p))
    return out


#: the most entries an indexed namelist variable may give (the TOML decks' own event and arc
#: limits are of this order; fracas.config.limits)
MAX_ENTRIES = 20_000


def _fill(tgt: _Target, part: str, prefix: tuple, f: NmlField, value: Any, src: str, group: str) -> None:
    """Write one namelist variable's value(s) into the part's data."""
    root = tgt.parts.setdefault(part, {})
    if f.name == "S" and group == "SMAG":
        _set(root, prefix + f.path, _as_list(value))
        tgt.mapped += 1
        return
    star = f.path.index("*") if f.indexed else None
    list_kind = f.kind in ("reals", "strs")
    if star is None:
        if list_kind:
            items = _as_list(value)
            if f.kind == "strs" and len(items) == 1 and isinstance(items[0], str) and " " in items[0].strip():
                items = items[0].split()  # hand-parsed: a blank-separated list in one string
            if any(x is None for x in _trim(items)):
                j = _trim(items).index(None) + 1
                raise DeckError(
                    f"{_where(src, group, f.name, j)}: not given; expected a value at every index from 1 to "
                    f"{len(_trim(items))} (the highest index written)"
                )
            conv = [_scalar(f, x, f"{_where(src, group, f.name)}({j + 1})") for j, x in enumerate(_trim(items))]
            _set(root, prefix + f.path, conv)
        else:
            if isinstance(value, list):
                raise DeckError(
                    f"{_where(src, group, f.name)} = {cut(_show(value), 40)}: expected one value, not a list"
                )
            _set(root, prefix + f.path, _scalar(f, value, _where(src, group, f.name)))
        tgt.origin[(part, _loc_text(prefix + f.path))] = f"${group}.{f.name}"
        tgt.mapped += 1
        return
    head, tail = f.path[:star], f.path[star + 1 :]
    entries = _as_list(value)
    if len(entries) > MAX_ENTRIES:  # a huge index (TON(3000000) = 1.0) would build millions of tables
        raise DeckError(
            f"{_where(src, group, f.name, len(entries))}: index {len(entries)}: expected at most {MAX_ENTRIES} entries"
        )
    if list_kind and entries and not any(isinstance(e, list) for e in entries):
        entries = [entries]  # NAME = a, b (no index): the values of entry 1
    for k, entry in enumerate(entries, start=1):
        if entry is None:
            continue
        if list_kind:
            items = _trim(_as_list(entry))
            if f.kind == "strs" and len(items) == 1 and isinstance(items[0], str) and " " in items[0].strip():
                items = items[0].split()
            if not items:
                continue  # NAME(:,k) all empty: entry k does not give it
            if any(x is None for x in items):
                raise DeckError(f"{_where(src, group, f.name, k)}: has an empty element")
            v = [_scalar(f, x, _where(src, group, f.name, k, j + 1)) for j, x in enumerate(items)]
        else:
            if isinstance(entry, list):
                raise DeckError(f"{_where(src, group, f.name, k)}: expected one value per entry")
            v = _scalar(f, entry, _where(src, group, f.name, k))
        path = prefix + head + (k - 1,) + tail + (("*",) if f.kind == "key" else ())
        _set(root, path, v)
        tgt.origin[(part, _loc_text(path))] = f"${group}.{f.name}({k})"
        tgt.mapped += 1


def _fix_lists(data: Any, src: str, where: str = "") -> Any:
    """Lists of tables with a hole (NAME(3) given, NAME(2) not) -> DeckError; recurse."""
    if isinstance(data, dict):
        return {k: _fix_lists(v, src, f"{where}.{k}" if where else k) for k, v in data.items()}
    if isinstance(data, list):
        if any(isinstance(x, dict) for x in data) and any(x is None for x in data):
            k = data.index(None)
            raise DeckError(f"{src}: {where}[{k}]: entry {k + 1} is not given (the arrays skip it)")
        return [_fix_lists(x, src, f"{where}[{i}]") for i, x in enumerate(data)]
    return data


def _keyed(data: dict, path: tuple, src: str, label: str) -> None:
    """A list of entries with "*" keys (OVBODY, CBODY, GMTYPE) -> a TOML table keyed by name."""
    cur: Any = data
    for p in path[:-1]:
        cur = cur.get(p) if isinstance(cur, dict) else None
        if cur is None:
            return
    items = cur.get(path[-1]) if isinstance(cur, dict) else None
    if not isinstance(items, list):
        return
    out: dict = {}
    for k, item in enumerate(items, start=1):
        if not isinstance(item, dict) or "*" not in item:
            raise DeckError(f"{src}: {label}({k}): not given (entry {k} needs its name)")
        key = item.pop("*")
        if key in out:
            raise DeckError(f"{src}: {label}({k}) = {key!r}: given twice")
        out[key] = item.pop("@value") if "@value" in item else item
    cur[path[-1]] = out


_STATE_KINDS = {1: "cartesian", 2: "elements", 3: "elements", 4: "spherical"}
_STATE_NAMES = {
    "cartesian": ("r_km", "v_km_s"),
    "elements": ("a_km", "e", "i_deg", "raan_deg", "argp_deg"),
    "spherical": ("r_km", "lat_deg", "lon_deg", "v_km_s", "gamma_deg", "sigma_deg"),
}


def _initial_state(data: dict, src: str, group: str, notes: list[str]) -> None:
    """ICOORD + X0(6) -> [initial_state.cartesian | elements | spherical] (ICOORD default 1)."""
    ist = data.get("initial_state")
    if not isinstance(ist, dict) or ("@kind" not in ist and "@x0" not in ist):
        return
    if "@kind" not in ist:
        notes.append(f"${group}.ICOORD not given: 1 (cartesian X0) assumed")
    code = ist.pop("@kind", 1)
    x0 = ist.pop("@x0", None)
    if code not in _STATE_KINDS:
        raise DeckError(
            f"{_where(src, group, 'ICOORD')} = {code}: expected 1 (cartesian), 2 (elements, mean "
            "anomaly), 3 (elements, true anomaly) or 4 (spherical)"
        )
    if x0 is None:
        raise DeckError(f"{_where(src, group, 'X0')}: required (the initial state, 6 values)")
    if len(x0) != 6:
        raise DeckError(f"{_where(src, group, 'X0')} = {cut(_show(x0), 40)}: expected 6 values, got {len(x0)}")
    kind = _STATE_KINDS[code]
    if kind == "cartesian":
        ist[kind] = {"r_km": x0[:3], "v_km_s": x0[3:]}
    elif kind == "elements":
        ist[kind] = dict(zip(_STATE_NAMES[kind], x0[:5]))
        ist[kind]["mean_anomaly_deg" if code == 2 else "true_anomaly_deg"] = x0[5]
    else:
        ist[kind] = dict(zip(_STATE_NAMES[kind], x0))


def _post(data: dict, part: str, src: str, group: str, notes: list[str]) -> None:
    """The fields that are not one-to-one: initial state, keyed tables, codes, arc numbers, sigmas."""
    if part in ("traj", "tom"):
        _initial_state(data, src, group, notes)
        _keyed(data, ("forces", "overrides"), src, f"${group}.OVBODY")
        _keyed(data, ("forces", "conic_bodies"), src, f"${group}.CBODY")
    if part == "tom":
        for k, c in enumerate(data.get("control", [])):
            links = c.get("links") if isinstance(c, dict) else None
            if isinstance(links, dict):
                names, values = links.get("@name", []), links.get("@value", [])
                if len(names) != len(values):
                    raise DeckError(
                        f"{_where(src, group, 'ULCOEF', k + 1)}: expected {len(names)} coefficients "
                        f"(one per ULINK(j,{k + 1}))"
                    )
                c["links"] = dict(zip(names, values))
        smag = data.get("smag")
        if isinstance(smag, dict) and "@s" in smag:
            cols = smag.pop("@s")  # f90nml: S(i,j) -> [column j][row i]
            cols = [_trim(_as_list(c)) for c in cols] if any(isinstance(c, list) for c in cols) else [[c] for c in cols]
            rows = max((len(c) for c in cols), default=0)
            s = []
            for i in range(rows):
                row = []
                for j, c in enumerate(cols):
                    x = c[i] if i < len(c) else None
                    row.append(_scalar(SMAG_FIELDS[0], x, _where(src, "SMAG", "S", j + 1, i + 1)))
                s.append(row)
            smag["s"] = s
    if part == "tsim":
        _keyed(data, ("insim", "team_changes"), src, "$INSIM.TCFLD")
    if part == "team":
        errcon = data.get("errcon")
        if isinstance(errcon, dict) and "@propagation" in errcon:
            errcon["propagation"] = "pdot" if errcon.pop("@propagation") else "phi"
        for k, g in enumerate(data.get("guidance", [])):
            if isinstance(g, dict) and "@arc" in g:
                arc = g.pop("@arc")
                if arc < 1:
                    raise DeckError(f"{_where(src, 'ERANAL', 'GARC', k + 1)} = {arc}: expected an arc number >= 1")
                g["arc"] = arc - 1
                notes.append(
                    f"$ERANAL.GARC({k + 1}) = {arc}: thrust arc {arc} is guidance[{k}].arc = {arc - 1} "
                    "(arcs from 1 -> from 0)"
                )
        for k, t in enumerate(data.get("tracking", [])):
            if isinstance(t, dict) and "sigma" in t:
                t["sigma"] = _msig(t.get("type"), t["sigma"], _where(src, "ERANAL", "MSIGMA", k + 1), notes)
        gencov = data.get("gencov")
        if isinstance(gencov, dict) and isinstance(gencov.get("measurement_sigma"), list):
            for k, item in enumerate(gencov["measurement_sigma"], start=1):
                if isinstance(item, dict) and "@value" in item:
                    typ = item.get("*")
                    item["@value"] = _msig(typ, item["@value"], _where(src, "GENCOV", "GMSIG", k), notes)
            _keyed(data, ("gencov", "measurement_sigma"), src, "$GENCOV.GMTYPE")


def _msig(typ: Any, value: float, where: str, notes: list[str]) -> float:
    """A measurement sigma in FRACAS units (km, km/s, rad) -> the TOML deck's unit for its type."""
    unit = SIGMA_UNITS.get(str(typ).strip().lower()) if typ is not None else None
    if unit is None:
        raise DeckError(
            f"{where} = {value:g}: its data type {typ!r} is not known, so its unit is not either "
            f"(expected a type of: {', '.join(SIGMA_UNITS)})"
        )
    out = value / unit[1]
    notes.append(f"{where.split(': ', 1)[1]} = {value:g} (FRACAS units) -> sigma = {out:.12g} {unit[0]}")
    return out


def _detect(groups: list[str], label: str | None, forced: str | None, src: str) -> tuple[str, str]:
    """(mode, how it was decided)."""
    present = set(groups)
    if forced is not None:
        if forced == "sweep":
            raise DeckError(
                f"{src}: --mode sweep: FRACAS has no sweep mode, so no namelist maps to a sweep deck "
                "(import the TEAM study, then write the [sweep] deck around it)"
            )
        if forced not in NAMELIST_MODES:
            raise DeckError(f"{src}: mode {forced!r}: expected one of: {', '.join(NAMELIST_MODES)}")
        need = {"propagate": ("DATA", "ERTRAJ"), "tom": ("DATA",), "team": ("ERTRAJ",), "tsim": ("INSIM",)}[forced]
        if not present & set(need):
            raise DeckError(
                f"{src}: mode {forced}: the deck has no ${' or $'.join(need)} namelist (it has ${', $'.join(groups)})"
            )
        return forced, "forced"
    if label is not None:
        mode = _MODE_LABELS[label]
        return mode, f"the deck's mode label {label!r}"
    if "INSIM" in present:
        return "tsim", "$INSIM present"
    if present & {"ERRCON", "ERTRAJ", "ERANAL", "GENCOV"}:
        return "team", "TEAM namelists present"
    if "SMAG" in present:
        return "tom", "$SMAG present"
    return "propagate", "$DATA only"


def import_namelist(
    text_or_path: str | Path, source: str | None = None, mode: str | None = None, name: str | None = None
) -> ImportResult:
    """A FRACAS namelist deck -> the TOML deck(s) of its mode, every unmapped field listed.

    ``text_or_path``: a Path, or a str: the deck's text when it has a newline or one of
    ``& $ =``, else a path; ``source``: the name in messages (default
    the path); ``mode``: force a mode (propagate, tom, team, tsim); ``name``: the stem of the
    companion decks (default the source's stem).  Mode (unless forced): the deck's mode label,
    else tsim with $INSIM, team with $ERRCON/$ERTRAJ/$ERANAL/$GENCOV, tom with $SMAG or TOM
    fields in $DATA, else propagate.  Groups the mode does not read, unknown groups, unknown
    fields and FRACAS fields without an equivalent are all reported in ``unmapped``.  A deck
    f90nml cannot read, a value of the wrong type or a missing required field: one DeckError
    naming the file, ``$GROUP.NAME`` and what was expected.  Each deck is validated by its
    schema (sub-decks named by file are checked by ``fracas validate`` once written)."""
    text, src = _read_text(text_or_path, source)
    label, outside = _scan_outside(text)
    parsed = _parse(text, src)
    groups = list(dict.fromkeys(g for g, _, _ in parsed))
    if mode is None and label is None and "DATA" in groups and not set(groups) & {"INSIM", "ERRCON", "ERTRAJ", "SMAG"}:
        tom_names = {f.name for f in TOM_FIELDS} - {f.name for f in TRAJECTORY_FIELDS}
        if any(k in tom_names for g, _, body in parsed if g == "DATA" for k in body):
            mode = "tom"
    the_mode, how = _detect(groups, label, mode, src)
    stem = name or (Path(src).stem if src and not src.startswith("<") else "imported")
    notes = [f"mode {the_mode} ({how})"]
    unmapped: list[Unmapped] = []
    for number, line in outside:
        unmapped.append(
            Unmapped(
                "-",
                f"line {number}",
                line,
                "text outside a namelist group: not read "
                "(event schedule cards are [[tracking]]/[[event]] arrays in $ERANAL)",
            )
        )
    tgt = _Target()
    used = _MODE_GROUPS[the_mode]
    if the_mode == "propagate" and "DATA" not in groups:
        used = ("ERTRAJ",)
    ertraj_inline = False
    for group, occ, body in parsed:
        if group not in KNOWN_GROUPS:
            for k, v in body.items():
                unmapped.append(Unmapped(group, k, v, f"unknown namelist group ${group}: not read"))
            if not body:
                unmapped.append(Unmapped(group, "-", "", f"unknown namelist group ${group}: not read"))
            continue
        if group not in used:
            for k, v in body.items():
                unmapped.append(Unmapped(group, k, v, f"${group} is not read in {the_mode} mode"))
            continue
        if occ > 0 and group != "INMAN":
            raise DeckError(f"{src}: ${group}: given {occ + 1} times; expected once (only $INMAN repeats)")
        table = {f.name: f for f in _table(group, the_mode)}
        traj_names = {f.name for f in TRAJECTORY_FIELDS}
        for key, value in body.items():
            if value is None or (isinstance(value, list) and not _trim(value)):
                continue  # NAME = (no value): not given
            f = table.get(key)
            if f is None:
                reason = KNOWN_UNMAPPED.get((group, key), "unknown field: not read")
                if group == "DATA" and key in {t.name for t in TOM_FIELDS} and key not in traj_names:
                    reason = f"a TOM input: not read in {the_mode} mode (--mode tom reads it)"
                unmapped.append(Unmapped(group, key, value, reason))
                continue
            part, prefix = _part_of(group, key, the_mode, occ)
            if part == "ignored":
                unmapped.append(Unmapped(group, key, value, f"not read in {the_mode} mode"))
                continue
            if part == "traj" and group == "ERTRAJ":
                ertraj_inline = True
            _fill(tgt, part, prefix, f, value, src, group)
            if f.scale != 1.0:
                what = _loc_text(tuple(x for x in f.path if x != "*"))
                notes.append(f"${group}.{key} ({f.unit or 'namelist unit'}) x {f.scale:g} -> {what}")
    for part, data in tgt.parts.items():
        grp = "DATA" if part in ("traj", "tom") and "DATA" in used else "ERTRAJ"
        _post(data, part, src, grp, notes)
        tgt.parts[part] = _fix_lists(data, src)
    return _assemble(tgt, the_mode, src, stem, notes, unmapped, ertraj_inline)


def _part_of(group: str, key: str, mode: str, occ: int) -> tuple[str, tuple]:
    """Which deck a group's field fills, and the path prefix there."""
    traj_names = {f.name for f in TRAJECTORY_FIELDS}
    if group == "DATA":
        return ("tom" if mode == "tom" else "traj"), ()
    if group == "SMAG":
        return "tom", ()
    if group == "ERTRAJ":
        if key in {f.name for f in ERTRAJ_FIELDS}:
            return ("team" if mode != "propagate" else "ignored"), ()
        if key in traj_names:
            return "traj", ()
    if group in ("INSIM",):
        return "tsim", ()
    if group == "INMAN":
        return "tsim", ("maneuver", occ)
    if mode == "propagate":
        return "ignored", ()
    return "team", ()


def _assemble(tgt: _Target, mode: str, src: str, stem: str, notes, unmapped, ertraj_inline) -> ImportResult:
    """Name the sub-decks, write the TOML texts, validate each by its schema."""
    from fracas.config.team import parse_team_deck
    from fracas.config.tom import parse_tom_deck
    from fracas.config.trajectory import parse_deck
    from fracas.config.tsim import parse_tsim_deck

    parts = tgt.parts
    parts.pop("ignored", None)
    companions: dict[str, str] = {}
    decks: dict[str, dict] = {}
    traj_name, team_name = f"{stem}_traj.toml", f"{stem}_team.toml"
    if mode in ("team", "tsim"):
        team = parts.setdefault("team", {})
        ertraj = team.setdefault("ertraj", {})
        has_team = any(k != "ertraj" for k in team) or "deck" in ertraj or ertraj_inline
        if mode == "tsim" and parts.get("tsim", {}).get("insim", {}).get("team_deck") and not has_team:
            parts.pop("team")
        else:
            if "deck" in ertraj and ertraj_inline:
                raise DeckError(
                    f"{src}: $ERTRAJ.DECK: names a trajectory deck and $ERTRAJ also gives trajectory "
                    "fields; give one or the other"
                )
            if "deck" not in ertraj:
                if "traj" not in parts:
                    raise DeckError(f"{src}: $ERTRAJ: required (the reference trajectory's fields, or DECK)")
                ertraj["deck"] = traj_name
                notes.append(f"the $ERTRAJ trajectory is written as {traj_name} (ertraj.deck)")
            team = {"mode": "team", **team}
            parts["team"] = team
            if mode == "tsim":
                insim = parts.setdefault("tsim", {}).setdefault("insim", {})
                if insim.get("team_deck"):
                    raise DeckError(
                        f"{src}: $INSIM.TEAMDK: names a TEAM deck and the deck also gives the TEAM "
                        "namelists; give one or the other"
                    )
                insim["team_deck"] = team_name
                notes.append(f"the TEAM namelists are written as {team_name} (insim.team_deck)")
        if mode == "tsim":
            tsim = parts.setdefault("tsim", {})
            tsim.setdefault("insim", {})
            parts["tsim"] = {"mode": "tsim", **tsim}
    if mode == "tom":
        tom = parts.pop("tom", {})
        tom = {"mode": "tom", **tom}
        parts = {"tom": tom}
    checks = {
        "traj": (parse_deck, traj_name),
        "team": (parse_team_deck, team_name),
        "tom": (parse_tom_deck, None),
        "tsim": (parse_tsim_deck, None),
    }
    main = {"propagate": "traj", "tom": "tom", "team": "team", "tsim": "tsim"}[mode]
    if main not in parts:
        raise DeckError(
            f"{src}: no fields of the {mode} mode's namelists ({', '.join('$' + g for g in _MODE_GROUPS[mode])})"
        )
    texts = {}
    for part, data in parts.items():
        parse, fname = checks[part]
        text = _toml_text(data, part)
        label = f"{src} (imported {part} deck)"
        try:
            parse(text, label)
        except DeckError as exc:
            raise _renamed(exc, label, src, part, tgt, mode) from None
        texts[part] = text
        decks[part] = data
        if part != main:
            companions[fname] = text
    head = _header(src, mode, unmapped)
    for fname in companions:
        companions[fname] = (
            f"# {'Imported'} by fracas import-namelist from {src} (a sub-deck of the {mode} deck)\n"
            + (companions[fname])
        )
    return ImportResult(
        toml=head + texts[main],
        mode=mode,
        companions=companions,
        unmapped=unmapped,
        notes=notes,
        mapped=tgt.mapped,
        decks=decks,
    )


_ARRAY = re.compile(r"= \[\n((?:    [^\[\]{}\n]*,\n)+)\]")


def _toml_text(data: dict, part: str) -> str:
    """TOML text of a deck's data: keys in the schema's order, short arrays on one line."""
    from fracas.config.team import TeamDeck
    from fracas.config.tom import TomDeck
    from fracas.config.trajectory import TrajectoryDeck
    from fracas.config.tsim import TsimDeck

    order = {
        "traj": list(TrajectoryDeck.model_fields),
        "team": list(TeamDeck.model_fields),
        "tom": list(TomDeck.model_fields) + list(TrajectoryDeck.model_fields),
        "tsim": list(TsimDeck.model_fields),
    }[part]
    rank = {k: i for i, k in enumerate(order)}
    data = dict(sorted(data.items(), key=lambda kv: rank.get(kv[0], len(rank))))
    text = tomli_w.dumps(data)

    def one_line(m: re.Match) -> str:
        items = [x.strip().rstrip(",") for x in m.group(1).splitlines()]
        line = "= [" + ", ".join(items) + "]"
        return line if len(line) <= 100 else m.group(0)

    return _ARRAY.sub(one_line, text)


def _header(src: str, mode: str, unmapped: list[Unmapped]) -> str:
    """The imported deck's header comment: where it came from and every field not mapped."""
    lines = [
        f"# Imported by fracas import-namelist from {src} ({mode} mode).",
        "# Units converted: see docs/namelist.md.",
    ]
    if unmapped:
        lines.append(f"# {len(unmapped)} namelist field(s) not mapped:")
        lines += [f"#   {u}" for u in unmapped]
    else:
        lines.append("# Every namelist field was mapped.")
    return "\n".join(lines) + "\n\n"


def _pattern_names(mode: str, part: str) -> list[tuple[str, str]]:
    """(TOML path pattern text, $GROUP.NAME) of every field that fills ``part`` (for error lines)."""
    out = []
    groups = {
        "traj": ("DATA" if mode in ("propagate", "tom") else "ERTRAJ",),
        "tom": ("DATA", "SMAG"),
        "team": ("ERRCON", "ERTRAJ", "ERANAL", "GENCOV"),
        "tsim": ("INSIM", "INMAN"),
    }[part]
    for g in groups:
        for f in _table(g, mode if mode != "propagate" else "tom"):
            if f.name == "ICOORD":
                continue
            parts = [p for p in f.path if not (isinstance(p, str) and p.startswith("@"))]
            pat = ""
            for p in parts:
                pat += "[*]" if p == "*" else (f"[{p}]" if isinstance(p, int) else ("." if pat else "") + p)
            if g == "INMAN":
                pat = "maneuver[*]." + pat
            out.append((pat, f"${g}.{f.name}"))
    return out


def _renamed(exc: DeckError, label: str, src: str, part: str, tgt: _Target, mode: str) -> DeckError:
    """A schema error of an imported deck, its TOML field named as the namelist field it came from."""
    patterns = _pattern_names(mode, part)
    lines = []
    for line in exc.problems or [str(exc)]:
        rest = line[len(label) + 2 :] if line.startswith(label + ": ") else line
        field_text = re.split(r" = |: ", rest, maxsplit=1)[0]
        name = tgt.origin.get((part, field_text))
        if name is None:
            best = ""
            for (p, loc), n in tgt.origin.items():
                if p == part and field_text.startswith(loc) and len(loc) > len(best):
                    best, name = loc, n
        if name is None:
            generic = re.sub(r"\[\d+\]", "[*]", field_text)
            index = re.findall(r"\[(\d+)\]", field_text)
            for pat, n in sorted(patterns, key=lambda x: -len(x[0])):
                if generic == pat or generic.startswith(pat + "."):
                    name = n + (f"({int(index[0]) + 1})" if "[*]" in pat and index else "")
                    break
        if name is None:
            inside = [n for pat, n in patterns if pat.startswith((generic + ".", generic + "["))]
            if inside:
                name = " / ".join(dict.fromkeys(inside[:3])) + (" ..." if len(inside) > 3 else "")
        where = f"{name} ({field_text})" if name else f"(no namelist field) {field_text}"
        lines.append(f"{src}: {where}{rest[len(field_text) :]}")
    from fracas.config.trajectory import deck_error

    return deck_error(lines)


# --------------------------------------------------------------------------- writing


def _load_config(toml_path_or_config):
    from fracas.config.modes import load_any

    if isinstance(toml_path_or_config, (str, Path)):
        return load_any(toml_path_or_config)
    return toml_path_or_config


def _dump(cfg) -> dict:
    return cfg.model_dump(mode="json", exclude_unset=True)


def _leaves(data: Any, path: tuple = ()) -> list[tuple[tuple, Any]]:
    """(path, value) of every value that is not a table (lists of tables are walked)."""
    if isinstance(data, dict):
        out = []
        for k, v in data.items():
            out += _leaves(v, path + (k,))
        return out
    if isinstance(data, list) and data and all(isinstance(x, dict) for x in data):
        out = []
        for i, v in enumerate(data):
            out += _leaves(v, path + (i,))
        return out
    return [(path, data)]


def _unkey(data: dict, path: tuple, value_key: bool = False) -> None:
    cur: Any = data
    for p in path[:-1]:
        cur = cur.get(p) if isinstance(cur, dict) else None
        if cur is None:
            return
    table = cur.get(path[-1]) if isinstance(cur, dict) else None
    if isinstance(table, dict):
        cur[path[-1]] = [{"*": k, "@value": v} if value_key else {"*": k, **v} for k, v in table.items()]


def _code_of(f: NmlField, v: Any) -> Any:
    for c, n in f.codes:
        if n == v:
            return c
    return v


def _write_group(fields: tuple[NmlField, ...], data: dict, prefix: tuple = ()) -> tuple[list, set]:
    """[(NAME, namelist value)] of the fields ``data`` holds, and the leaf paths they took."""
    leaves = _leaves(data)
    taken: set = set()
    out = []
    for f in fields:
        fpath = prefix + f.path
        if f.kind == "key":
            fpath = fpath + ("*",)
        comp = fpath[-1] if isinstance(fpath[-1], int) else None
        if comp is not None:
            fpath = fpath[:-1]
        star = fpath.index("*") if "*" in fpath else None
        values: dict[int, Any] = {}
        for lp, v in leaves:
            if len(lp) != len(fpath):
                continue
            if all(a == b or (b == "*" and isinstance(a, int)) for a, b in zip(lp, fpath)):
                if v is None:
                    continue
                k = lp[star] if star is not None else 0
                val = v[comp] if comp is not None else v
                if f.kind == "code":
                    val = _code_of(f, val)
                if f.kind in ("real", "reals") and f.scale != 1.0:
                    val = [x / f.scale for x in val] if isinstance(val, list) else val / f.scale
                values[k] = val
                taken.add(lp)
        if not values:
            continue
        if star is None:
            out.append((f.name, values[0]))
        else:
            n = max(values) + 1
            arr = [values.get(k) for k in range(n)]
            if f.kind in ("reals", "strs"):
                width = max(len(a) for a in arr if a is not None)
                arr = [(a or []) + [None] * (width - len(a or [])) for a in arr]
            out.append((f.name, arr))
    return out, taken


def _traj_block(tdump: dict) -> tuple[list, set]:
    """$DATA / $ERTRAJ trajectory values, ICOORD + X0 included."""
    ist = tdump.get("initial_state", {})
    extra = []
    if "cartesian" in ist:
        c = ist["cartesian"]
        extra = [("ICOORD", 1), ("X0", list(c["r_km"]) + list(c["v_km_s"]))]
    elif "elements" in ist:
        e = ist["elements"]
        true = "true_anomaly_deg" in e
        extra = [
            ("ICOORD", 3 if true else 2),
            (
                "X0",
                [
                    e["a_km"],
                    e["e"],
                    e["i_deg"],
                    e.get("raan_deg", 0.0),
                    e.get("argp_deg", 0.0),
                    e["true_anomaly_deg" if true else "mean_anomaly_deg"],
                ],
            ),
        ]
    elif "spherical" in ist:
        s = ist["spherical"]
        extra = [("ICOORD", 4), ("X0", [s[k] for k in _STATE_NAMES["spherical"]])]
    data = {k: v for k, v in tdump.items() if k != "mode"}
    data["initial_state"] = {k: v for k, v in ist.items() if k not in ("cartesian", "elements", "spherical")}
    _unkey(data, ("forces", "overrides"))
    _unkey(data, ("forces", "conic_bodies"))
    vals, taken = _write_group(tuple(f for f in TRAJECTORY_FIELDS if f.name not in ("ICOORD", "X0")), data)
    missed = {lp for lp, _ in _leaves(data) if lp not in taken and lp != ("initial_state",)}
    ordered = []
    for name, v in vals:
        ordered.append((name, v))
        if name in ("FRAME",) or (name == "CENTRE" and "FRAME" not in dict(vals)):
            ordered += extra
            extra = []
    return ordered + extra, missed


def _missed(data: dict, taken: set, skip: tuple = ()) -> list[str]:
    return [
        f"{_loc_text(lp)} = {cut(_show(v), 40)}"
        for lp, v in _leaves(data)
        if lp not in taken and not (skip and lp[: len(skip)] == skip) and lp != ("mode",)
    ]


def _nml(groups: list[tuple[str, list]]) -> str:
    """The groups as f90nml writes them (upper case, shortest round-trip floats)."""
    items = []
    for gname, values in groups:
        if not values:
            continue
        nml = f90nml.Namelist([(n.lower(), v) for n, v in values])
        items.append((gname.lower(), nml))
    out = f90nml.Namelist()
    for gname, nml in items:
        if gname in out:
            prev = out[gname]
            out[gname] = (prev if isinstance(prev, list) else [prev]) + [nml]
        else:
            out[gname] = nml
    out.uppercase = True
    out.float_format = ""
    out.end_comma = False
    return str(out) if items else ""


def namelist_from_deck(toml_path_or_config, dollar: bool = False, inline: bool = True) -> str:
    """A FRACAS-style namelist deck from a TOML deck (path or validated config), any mode but sweep.

    The inverse of :func:`import_namelist` for the fields the mapping covers (same names and
    unit conversions); every TOML field it cannot write is listed in a ``!`` comment at the
    top.  ``dollar``: write ``$GROUP ... $END`` (FRACAS) instead of ``&GROUP ... /``;
    ``inline``: write a TEAM deck's trajectory into $ERTRAJ (and a TSIM deck's TEAM study into
    the TEAM namelists), else name them by file ($ERTRAJ.DECK, $INSIM.TEAMDK)."""
    from fracas.config.team import TeamDeck
    from fracas.config.tom import TomDeck, tom_trajectory_deck
    from fracas.config.trajectory import TrajectoryDeck
    from fracas.config.tsim import TsimDeck, tsim_team_deck

    cfg = _load_config(toml_path_or_config)
    missed: list[str] = []
    groups: list[tuple[str, list]] = []
    src = cfg.source_path or "<deck>"
    if isinstance(cfg, TrajectoryDeck):
        label = "PROPAGATE"
        vals, miss = _traj_block(_dump(cfg))
        groups.append(("DATA", vals))
        missed += [f"{_loc_text(lp)}" for lp in miss]
    elif isinstance(cfg, TomDeck):
        label = "TOM"
        d = _dump(cfg)
        traj = tom_trajectory_deck(cfg)
        tvals, miss = _traj_block(_dump(traj))
        missed += [_loc_text(lp) for lp in miss]
        tomd = {k: v for k, v in d.items() if k in ("tom", "control", "target", "grid", "smag")}
        for c in tomd.get("control", []):
            if "links" in c:
                c["links"] = {"@name": list(c["links"]), "@value": list(c["links"].values())}
        smag = tomd.pop("smag", None)
        vals, taken = _write_group(TOM_FIELDS, tomd)
        vals = [(n, v) for n, v in vals if n not in ("ULINK", "ULCOEF")] + _links(tomd)
        taken |= {lp for lp, _ in _leaves(tomd) if "links" in lp}
        missed += _missed(tomd, taken)
        if "title" in d and "title" not in _dump(traj):
            tvals = [("TITLE", d["title"])] + tvals
        groups.append(("DATA", tvals + vals))
        if smag is not None:
            s_cols = [[row[j] for row in smag["s"]] for j in range(len(smag["g"]))] if smag["s"] else []
            groups.append(("SMAG", ([("S", s_cols)] if s_cols else []) + [("G", smag["g"])]))
    elif isinstance(cfg, TeamDeck):
        label = "TEAM"
        groups += _team_groups(cfg, inline, missed)
    elif isinstance(cfg, TsimDeck):
        label = "TSIM"
        d = _dump(cfg)
        insim = dict(d.get("insim", {}))
        if "team_changes" in insim:
            insim["team_changes"] = dict(insim["team_changes"])
        data = {"insim": insim, "output": d.get("output", {}), "title": d.get("title")}
        if data["title"] is None:
            data.pop("title")
        _unkey(data, ("insim", "team_changes"), value_key=True)
        if inline:
            insim.pop("team_deck", None)
        vals, taken = _write_group(INSIM_FIELDS, data)
        missed += _missed(data, taken)
        groups.append(("INSIM", vals))
        for m in d.get("maneuver", []):
            mv, mt = _write_group(INMAN_FIELDS, m)
            missed += ["maneuver." + x for x in _missed(m, mt)]
            groups.append(("INMAN", mv))
        if inline:
            groups += _team_groups(tsim_team_deck(cfg), True, missed)
    else:
        raise DeckError(
            f"{src}: a {getattr(cfg, 'mode', type(cfg).__name__)} deck has no FRACAS namelist form "
            "(FRACAS reads TOM, TEAM and TSIM decks)"
        )
    head = [
        f"! FRACAS namelist deck written by fracas from {src}",
        "! units: km, km/s, kg, kW, deg, days (docs/namelist.md)",
    ]
    for m in missed:
        head.append(f"! not written (no namelist field): {m}")
    body = _nml(groups)
    if dollar:
        body = re.sub(r"^&(\w+)", r"$\1", body, flags=re.MULTILINE)
        body = re.sub(r"^/\s*$", "$END", body, flags=re.MULTILINE)
    return "\n".join(head) + "\n" + label + "\n" + body


def _links(tomd: dict) -> list:
    controls = tomd.get("control", [])
    if not any("links" in c for c in controls):
        return []
    names = [c.get("links", {}).get("@name", []) for c in controls]
    coefs = [c.get("links", {}).get("@value", []) for c in controls]
    width = max(len(n) for n in names)
    return [
        ("ULINK", [n + [None] * (width - len(n)) for n in names]),
        ("ULCOEF", [c + [None] * (width - len(c)) for c in coefs]),
    ]


def _team_groups(cfg, inline: bool, missed: list[str]) -> list[tuple[str, list]]:
    """$ERRCON, $ERTRAJ, $ERANAL, $GENCOV of a TEAM deck."""
    from fracas.config.trajectory import load_deck

    d = _dump(cfg)
    d.pop("mode", None)
    for g in d.get("guidance", []):
        if "arc" in g:
            g["@arc"] = g.pop("arc") + 1  # arcs from 1 in the namelist
    for t in d.get("tracking", []):
        if "sigma" in t:
            t["sigma"] = t["sigma"] * SIGMA_UNITS[t["type"]][1]
    gencov = d.get("gencov")
    if isinstance(gencov, dict) and "measurement_sigma" in gencov:
        gencov["measurement_sigma"] = {k: v * SIGMA_UNITS[k][1] for k, v in gencov["measurement_sigma"].items()}
        _unkey(d, ("gencov", "measurement_sigma"), value_key=True)
    errcon = d.get("errcon", {})
    if "propagation" in errcon:
        errcon["@propagation"] = errcon.pop("propagation") == "pdot"
    out = []
    ev, et = _write_group(ERRCON_FIELDS, {"errcon": errcon})
    missed += _missed({"errcon": errcon}, et)
    out.append(("ERRCON", ev))
    ertraj_data = {"ertraj": dict(d.get("ertraj", {})), "stm": d.get("stm", {})}
    tvals: list = []
    if inline:
        ertraj_data["ertraj"].pop("deck", None)
        traj = load_deck(cfg.resolve(cfg.ertraj.deck))
        tvals, miss = _traj_block(_dump(traj))
        missed += ["ertraj.deck: " + _loc_text(lp) for lp in miss]
    rv, rt = _write_group(ERTRAJ_FIELDS, ertraj_data)
    missed += _missed(ertraj_data, rt)
    out.append(("ERTRAJ", rv + tvals))
    rest = {k: v for k, v in d.items() if k not in ("errcon", "ertraj", "stm")}
    gen = rest.pop("gencov", None)
    if gen is not None and "enabled" in gen:
        rest["gencov"] = {"enabled": gen.pop("enabled")}
    av, at = _write_group(ERANAL_FIELDS, rest)
    missed += _missed(rest, at)
    out.append(("ERANAL", av))
    if gen:
        gd = {"gencov": gen}
        gv, gt = _write_group(GENCOV_FIELDS, gd)
        missed += _missed(gd, gt)
        out.append(("GENCOV", gv if gv else []))
    if gen is not None and not gen and not any(n == "LGENCV" for n, _ in av):
        out[2][1].append(("LGENCV", True))  # an empty [gencov] table: enabled (its default)
    return out
