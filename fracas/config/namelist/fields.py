"""The namelist <-> TOML mapping, part 1: the trajectory and TOM namelists.

:class:`NmlField` (one namelist variable and the TOML field it fills), the modes and groups a
FRACAS deck may hold (report §3), and the tables of ``$DATA`` (:data:`TRAJECTORY_FIELDS`, also
``$ERTRAJ``'s trajectory fields, and :data:`TOM_FIELDS`) and ``$SMAG`` (:data:`SMAG_FIELDS`),
report §3.1.  The TEAM and TSIM tables are in :mod:`fracas.config.namelist.team_fields`.
"""

from __future__ import annotations

from dataclasses import dataclass

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


def _f(
    name: str, path: str | tuple, kind: str, doc: str, scale: float = 1.0, codes: tuple = (), unit: str = ""
) -> NmlField:
    """A table row: ``path`` given as dotted text (or as a tuple when it holds ints or "@" keys)."""
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
