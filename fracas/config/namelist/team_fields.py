"""The namelist <-> TOML mapping, part 2: the TEAM and TSIM namelists, and lookups over all groups.

The tables of ``$ERRCON``, ``$ERTRAJ`` (besides its trajectory fields), ``$ERANAL`` and
``$GENCOV`` (TEAM, report §3.2), ``$INSIM`` and ``$INMAN`` (TSIM, report §3.3); the FRACAS
inputs with no fracas equivalent (:data:`KNOWN_UNMAPPED`); which fields a group holds in a mode
(:func:`_table`) and every group's table (:func:`namelist_fields`, for docs/namelist.md).
"""

from __future__ import annotations

from fracas.config.namelist.fields import SMAG_FIELDS, TOM_FIELDS, TRAJECTORY_FIELDS, NmlField, _f

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


def _outputs(title: str) -> tuple[NmlField, ...]:
    """RESULT, PLOT and TITLE: a study's or run's output files and title (fracas)."""
    return (
        _f("RESULT", "output.results", "str", "results file (fracas)"),
        _f("PLOT", "output.plot", "str", "plot file (fracas)"),
        _f("TITLE", "title", "str", title),
    )


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
    *_outputs("the study's title"),
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
    *_outputs("the run's title"),
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
