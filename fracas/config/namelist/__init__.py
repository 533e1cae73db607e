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

The package: :mod:`~fracas.config.namelist.fields` and
:mod:`~fracas.config.namelist.team_fields` (the mapping tables),
:mod:`~fracas.config.namelist.scan` (reading the text), :mod:`~fracas.config.namelist.values`
and :mod:`~fracas.config.namelist.post` (namelist values -> TOML data),
:mod:`~fracas.config.namelist.importer` (:func:`import_namelist`),
:mod:`~fracas.config.namelist.writer` (:func:`namelist_from_deck`) and
:mod:`~fracas.config.namelist.results` (what an import returns).

Nothing here imports JAX.
"""

from fracas.config.namelist.fields import (
    KNOWN_GROUPS,
    NAMELIST_MODES,
    SMAG_FIELDS,
    TOM_FIELDS,
    TRAJECTORY_FIELDS,
    NmlField,
)
from fracas.config.namelist.importer import import_namelist
from fracas.config.namelist.results import ImportResult, Unmapped
from fracas.config.namelist.team_fields import (
    ERANAL_FIELDS,
    ERRCON_FIELDS,
    ERTRAJ_FIELDS,
    GENCOV_FIELDS,
    INMAN_FIELDS,
    INSIM_FIELDS,
    KNOWN_UNMAPPED,
    namelist_fields,
)
from fracas.config.namelist.values import MAX_ENTRIES
from fracas.config.namelist.writer import namelist_from_deck

__all__ = [
    "ImportResult",
    "Unmapped",
    "import_namelist",
    "namelist_from_deck",
    "namelist_fields",
    "NAMELIST_MODES",
    "KNOWN_GROUPS",
    "KNOWN_UNMAPPED",
    "MAX_ENTRIES",
    "NmlField",
    "TRAJECTORY_FIELDS",
    "TOM_FIELDS",
    "SMAG_FIELDS",
    "ERRCON_FIELDS",
    "ERTRAJ_FIELDS",
    "ERANAL_FIELDS",
    "GENCOV_FIELDS",
    "INSIM_FIELDS",
    "INMAN_FIELDS",
]
