"""Legacy FRACAS namelist decks <-> TOML decks (fracas/config/namelist/, ``fracas import-namelist``).

References: the bundled TOML decks themselves (a namelist written from a deck must import back
to the same validated deck, field by field, and propagate to the same final state), the
report's namelist list (§3: every field the import cannot map is reported by namelist and
name), f90nml's reading of the ``&GROUP ... /`` form (the ``$GROUP ... $END`` form must read
alike), and the CLI conventions of tests/test_cli.py (one-line errors, exit 2, no traceback).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fracas.cli import main
from fracas.config.namelist import import_namelist, namelist_from_deck
from fracas.config.team import TeamDeck
from fracas.config.tom import TomDeck, tom_trajectory_deck
from fracas.config.tsim import TsimDeck, tsim_team_deck
from fracas.errors import DeckError
from fracas.modes import check_path, load_any

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data"
NAMELISTS = REPO / "namelists"
LEGACY = NAMELISTS / "legacy"
#: every float survives the unit conversions (hours <-> days, m <-> km, % <-> fraction) to the
#: last bits: x / 24 * 24 and x * 1e-6 / 1e-6 may differ from x by an ulp or two
REL = 1e-14

ROUND_TRIP = [
    NAMELISTS / "leo_j2.toml",  # trajectory
    NAMELISTS / "mercury_approach_traj.toml",  # trajectory with elements
    DATA / "team_small.toml",  # TEAM
    NAMELISTS / "earth_mars_team.toml",  # TEAM
    NAMELISTS / "mercury_approach_guidance.toml",  # TEAM with guidance
    DATA / "hohmann_tom.toml",  # TOM, impulses
    NAMELISTS / "earth_mars_tom.toml",  # TOM, thrust arcs
    DATA / "tom_fd_radius.toml",  # TOM with linked controls
    DATA / "tsim_small.toml",  # TSIM
    NAMELISTS / "earth_mars_tsim.toml",  # TSIM with team_changes
    NAMELISTS / "earth_mars_tsim_nonlinear.toml",  # TSIM with an $INMAN
]


def fracas(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def deep_dump(deck) -> dict:
    """The validated deck's values with every sub-deck it names by file replaced by that deck's
    values (the import writes sub-decks under new names)."""
    out = deck.model_dump(mode="json")
    if isinstance(deck, TeamDeck):
        out["ertraj"]["deck"] = load_any(deck.resolve(deck.ertraj.deck)).model_dump(mode="json")
    elif isinstance(deck, TsimDeck):
        out["insim"]["team_deck"] = deep_dump(tsim_team_deck(deck))
    elif isinstance(deck, TomDeck):
        out.pop("trajectory")
        traj = tom_trajectory_deck(deck).model_dump(mode="json")
        traj["title"] = traj["title"] or out["title"]
        out["trajectory_deck"] = traj
    return out


def differences(a, b, path="") -> list[str]:
    """Field-by-field differences of two dumps (floats to REL)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [
            d
            for k in sorted(set(a) | set(b))
            for d in differences(a.get(k, "<absent>"), b.get(k, "<absent>"), f"{path}.{k}")
        ]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float) and math.isclose(a, b, rel_tol=REL, abs_tol=0.0):
        return []
    return [] if a == b and type(a) is type(b) else [f"{path}: {a!r} != {b!r}"]


def write_import(result, out: Path) -> Path:
    out.write_text(result.toml, encoding="utf-8")
    for name, text in result.companions.items():
        (out.parent / name).write_text(text, encoding="utf-8")
    return out


# ---------------------------------------------------------------- round trip


@pytest.mark.parametrize("deck", ROUND_TRIP, ids=lambda p: p.name)
def test_round_trip_equals_the_bundled_toml_deck(deck, tmp_path):
    """namelist_from_deck(deck) imported back validates (``fracas validate``'s check) and is the
    same deck, field by field, sub-decks included; nothing is reported unmapped or unwritten."""
    text = namelist_from_deck(load_any(deck))
    assert "! not written" not in text, text
    result = import_namelist(text, str(tmp_path / "old.nml"), name="new")
    assert result.unmapped == []
    out = write_import(result, tmp_path / "new.toml")
    kind, problems = check_path(out)
    assert problems == [], problems
    assert kind == load_any(deck).mode
    assert differences(deep_dump(load_any(deck)), deep_dump(load_any(out))) == []


def test_round_trip_validates_with_fracas_validate(tmp_path):
    """The CLI's ``fracas validate`` accepts the imported TEAM deck and its trajectory deck."""
    nml = tmp_path / "team.nml"
    nml.write_text(namelist_from_deck(load_any(DATA / "team_small.toml")), encoding="utf-8")
    r = fracas("import-namelist", nml, "-o", tmp_path / "team.toml")
    assert r.exit_code == 0, r.output
    v = fracas("validate", tmp_path / "team.toml", tmp_path / "team_traj.toml")
    assert v.exit_code == 0, v.output
    assert "ok: " in v.output and "(team)" in v.output and "(propagate)" in v.output


def test_round_trip_gives_the_same_propagation_as_the_toml_deck(tmp_path):
    """leo_j2 propagated from the TOML deck and from its namelist import: the same final state
    to 1e-12 relative (the same deck values; in practice bit for bit)."""
    from fracas.modes.propagate import propagate_deck

    deck = NAMELISTS / "leo_j2.toml"
    out = write_import(import_namelist(namelist_from_deck(load_any(deck)), "leo.nml"), tmp_path / "leo.toml")
    a, _ = propagate_deck(deck, tmp_path / "a.h5")
    b, _ = propagate_deck(out, tmp_path / "b.h5")
    for x, y in ((a.r_final_km, b.r_final_km), (a.v_final_km_s, b.v_final_km_s)):
        np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=1e-12, atol=0.0)
    assert a.t_final_s == b.t_final_s and a.n_steps == b.n_steps


@pytest.mark.parametrize("name", sorted(p.name for p in LEGACY.glob("*.nml")))
def test_legacy_example_decks_equal_the_toml_decks_they_came_from(name, tmp_path):
    """namelists/legacy/*.nml (written from namelists/<same stem>.toml, then hand-tidied: upper
    case, T/F, $GROUP ... $END) import, validate and equal their TOML originals."""
    out = tmp_path / name.replace(".nml", ".toml")
    r = fracas("import-namelist", LEGACY / name, "-o", out)
    assert r.exit_code == 0, r.output
    assert check_path(out)[1] == []
    original = load_any(NAMELISTS / name.replace(".nml", ".toml"))
    assert differences(deep_dump(original), deep_dump(load_any(out))) == []
    if name == "earth_mars_team.nml":  # the one field the example keeps that has no equivalent
        assert "  $ERANAL.IPRINT = 1: no equivalent (print control)" in r.output


# ---------------------------------------------------------------- what is not mapped

UNMAPPED_DECK = """\
PROPAGATE
$DATA
  TITLE = 'LEO', EPOCH = '2030-01-01T00:00:00', CENTRE = 'EARTH', FRAME = 'EME2000',
  ICOORD = 1, X0 = 7000.0, 0.0, 0.0, 0.0, 7.5, 1.0,
  MASS0 = 1000.0, LJ2 = T, IPRINT = 2, XYZZY = 3, MAXIT = 4,
  TFINAL = 1.0, DTOUT = 0.01
$END
$PLOTS XMIN = 1.0, LABEL = 'x' $END
$ERANAL IPRINT = 1 $END
 1 0.5 2.0 schedule card
"""


def test_every_unmapped_field_is_reported_with_namelist_and_name(tmp_path):
    """Against the deck's own fields: an unknown field, a FRACAS field without equivalent, a TOM
    field in a trajectory deck, an unknown group (each of its fields), a group the mode does not
    read and text outside any group are each reported; the deck still imports and validates."""
    nml = tmp_path / "old.nml"
    nml.write_text(UNMAPPED_DECK, encoding="utf-8")
    result = import_namelist(nml)
    got = {(u.namelist, u.name): u for u in result.unmapped}
    assert set(got) == {
        ("DATA", "IPRINT"),
        ("DATA", "XYZZY"),
        ("DATA", "MAXIT"),
        ("PLOTS", "XMIN"),
        ("PLOTS", "LABEL"),
        ("ERANAL", "IPRINT"),
        ("-", "line 10"),
    }
    assert str(got["DATA", "IPRINT"]).startswith("$DATA.IPRINT = 2: no equivalent (print control")
    assert str(got["DATA", "XYZZY"]) == "$DATA.XYZZY = 3: unknown field: not read"
    assert "unknown namelist group $PLOTS" in got["PLOTS", "XMIN"].reason
    assert "not read in propagate mode" in got["ERANAL", "IPRINT"].reason
    assert got["PLOTS", "XMIN"].value == 1.0
    for u in result.unmapped:  # the deck's header lists them as comments
        assert f"#   {u}" in result.toml
    out = tmp_path / "new.toml"
    r = fracas("import-namelist", nml, "-o", out)
    assert r.exit_code == 0, r.output
    assert "7 not mapped" in r.output
    assert "  $DATA.XYZZY = 3: unknown field: not read" in r.output
    assert "  $PLOTS.LABEL = 'x': unknown namelist group $PLOTS: not read" in r.output
    assert all(len(line) <= 80 for line in r.output.splitlines() if str(tmp_path) not in line), r.output
    assert out.read_text().startswith(f"# Imported by fracas import-namelist from {nml}")
    assert check_path(out)[1] == []


def test_mode_detection_and_forced_mode():
    """The deck's mode label decides, else its namelists; --mode forces one; sweep is refused."""
    team = namelist_from_deck(load_any(DATA / "team_small.toml"))
    assert import_namelist(team, "t.nml").mode == "team"
    unlabelled = team.replace("\nTEAM\n", "\n")
    assert import_namelist(unlabelled, "t.nml").mode == "team"
    forced = import_namelist(team, "t.nml", mode="propagate")
    assert forced.mode == "propagate" and 'centre = "sun"' in forced.toml
    assert any(u.namelist == "ERANAL" and "not read in propagate mode" in u.reason for u in forced.unmapped)
    with pytest.raises(DeckError, match="FRACAS has no sweep mode"):
        import_namelist(team, "t.nml", mode="sweep")
    with pytest.raises(DeckError, match=r"t.nml: mode tsim: the deck has no \$INSIM namelist"):
        import_namelist(team, "t.nml", mode="tsim")


def test_units_are_converted_as_documented():
    """docs/namelist.md: $ERANAL.MINTVL days -> hours, MSIGMA km (range) -> m and km/s (Doppler)
    -> mm/s, $ERTRAJ.DTSTM days -> hours, $DATA.PERCEN percent -> fraction, $ERANAL.GARC from 1
    -> arc from 0; each conversion is in the notes."""
    team = import_namelist(LEGACY / "earth_mars_team.nml")
    d = team.decks["team"]
    assert d["tracking"][3]["sigma"] == 2.0 and d["tracking"][3]["interval_hours"] == 24.0
    assert math.isclose(d["tracking"][0]["sigma"], 1.0, rel_tol=REL) and d["stm"]["grid_hours"] == 2.0
    assert any("$ERANAL.MSIGMA(4) = 0.002 (FRACAS units) -> sigma = 2 m" in n for n in team.notes)
    text = namelist_from_deck(load_any(NAMELISTS / "earth_mars_tom.toml")).replace(
        "    MAXIT", "    PERCEN = 50.0\n    MAXIT"
    )
    assert import_namelist(text, "x.nml").decks["tom"]["tom"]["correction_fraction"] == 0.5
    guid = import_namelist(namelist_from_deck(load_any(DATA / "tsim_team.toml")), "g.nml")
    assert guid.decks["team"]["guidance"][1]["arc"] == 1
    assert any("$ERANAL.GARC(2) = 2" in n for n in guid.notes)


def test_each_inman_group_is_one_maneuver(tmp_path):
    """§3.3: "each maneuver must have its own $INMAN": two groups -> two [[maneuver]] entries in
    deck order, checked against the TEAM deck's guidance events by ``fracas validate``."""
    text = namelist_from_deck(load_any(NAMELISTS / "earth_mars_tsim_nonlinear.toml"))
    at = text.index("&INMAN")
    text = text[:at] + "&INMAN\n    NAME = 'lt1'\n    LAW = 1\n/\n" + text[at:]
    result = import_namelist(text, str(tmp_path / "x.nml"), name="x")
    assert [(m["name"], m["law"]) for m in result.decks["tsim"]["maneuver"]] == [
        ("lt1", "linear"),
        ("tcm1", "nonlinear"),
    ]
    assert check_path(write_import(result, tmp_path / "x.toml"))[1] == []


# ---------------------------------------------------------------- the two group forms


def test_dollar_end_and_ampersand_slash_forms_read_alike():
    """f90nml reads &GROUP ... / ; FRACAS wrote $GROUP ... $END (and &GROUP ... &END): the same
    deck in each form gives the same TOML."""
    amp = namelist_from_deck(load_any(DATA / "team_small.toml"))
    dollar = namelist_from_deck(load_any(DATA / "team_small.toml"), dollar=True)
    assert "$ERANAL" in dollar and "$END" in dollar and "&ERANAL" in amp
    amp_end = amp.replace("\n/\n", "\n&END\n")
    texts = {import_namelist(t, "x.nml").toml for t in (amp, dollar, amp_end)}
    assert len(texts) == 1


# ---------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "text, expected",
    [
        ("&DATA MASS0 = 'heavy' /\n", r"^old\.nml: \$DATA\.MASS0 = 'heavy': expected a number$"),
        ("&DATA LJ2 = 3 /\n", r"^old\.nml: \$DATA\.LJ2 = 3: expected a logical \(T or F\)$"),
        ("&DATA IATT(2) = 7 /\n", r"^old\.nml: \$DATA\.IATT\(2\) = 7: expected one of 1 \(velocity\)"),
        ("&DATA X0 = 1, 2, 3 /\n", r"^old\.nml: \$DATA\.X0 = 1\.0, 2\.0, 3\.0: expected 6 values, got 3$"),
        (
            "&DATA EPOCH = '2030-01-01', CENTRE = 'earth', X0 = 7000,0,0,0,7.5,0, TFINAL = 1 /\n",
            r"^old\.nml: \$DATA\.MASS0 / .*\(spacecraft\): required$",
        ),
        (
            "&DATA EPOCH = '2030-01-01', CENTRE = 'earth', X0 = 7000,0,0,0,7.5,0, MASS0 = -1, TFINAL = 1 /\n",
            r"^old\.nml: \$DATA\.MASS0 \(spacecraft\.mass_kg\) = -1\.0: must be > 0$",
        ),
        (
            "&DATA EPOCH='2030-01-01', CENTRE='earth', X0=7000,0,0,0,7.5,0, MASS0=1, TFINAL=1, TON=0,1, TOFF=1 /\n",
            r"^old\.nml: \$DATA\.TOFF\(2\) \(thrust_arc\[1\]\.stop_days\): required",
        ),
        ("&DATA X = 'unterminated /\n", r"^old\.nml: not a readable namelist deck"),
        ("&DATA X = 1\n", r"^old\.nml: not a readable namelist deck \(End-of-file"),
        ("no groups at all\n", r"^old\.nml: no namelist groups found"),
        ("&ERANAL IFILT = 1 /\n&ERANAL IFILT = 2 /\n", r"^old\.nml: \$ERANAL: given 2 times; expected once"),
    ],
)
def test_errors_are_one_line_naming_file_namelist_and_field(text, expected):
    """Wrong types, missing required fields, schema failures and unreadable text: one DeckError
    line naming the file, $GROUP.NAME (and the TOML field) and what was expected."""
    with pytest.raises(DeckError) as info:
        import_namelist(text, "old.nml")
    msg = str(info.value)
    assert "\n" not in msg
    assert re.search(expected, msg), msg


def test_missing_or_unreadable_file_is_one_line(tmp_path):
    with pytest.raises(DeckError, match=r"nope\.nml: no such file$"):
        import_namelist(tmp_path / "nope.nml")
    with pytest.raises(DeckError, match="is a directory"):
        import_namelist(tmp_path)


def test_cli_errors_exit_2_without_traceback(tmp_path):
    """A missing file, a wrong type: ``fracas: error: ...`` on one line, exit 2, no traceback."""
    bad = tmp_path / "bad.nml"
    bad.write_text("&DATA MASS0 = 'heavy' /\n", encoding="utf-8")
    for nml in (tmp_path / "missing.nml", bad):
        r = subprocess.run(
            [sys.executable, "-m", "fracas.cli", "import-namelist", str(nml), "-o", str(tmp_path / "x.toml")],
            capture_output=True,
            text=True,
            cwd=REPO,
            timeout=120,
        )
        assert r.returncode == 2, r.stderr
        assert r.stderr.startswith("fracas: error: ") and r.stderr.count("\n") == 1, r.stderr
        assert "Traceback" not in r.stderr
        assert str(nml) in r.stderr
        assert not (tmp_path / "x.toml").exists()


def test_refuses_to_overwrite_without_force(tmp_path):
    out = tmp_path / "leo.toml"
    out.write_text("# mine\n", encoding="utf-8")
    r = fracas("import-namelist", LEGACY / "leo_j2.nml", "-o", out)
    assert r.exit_code == 2
    assert "exists; use --force" in r.output
    assert out.read_text() == "# mine\n"
    r = fracas("import-namelist", LEGACY / "leo_j2.nml", "-o", out, "--force")
    assert r.exit_code == 0, r.output
    assert out.read_text().startswith("# Imported by fracas import-namelist")


def test_cli_mode_option_and_companion_files(tmp_path):
    """--mode forces the mode (sweep refused, exit 2); a companion deck that exists is refused
    like the deck itself; the companions are written beside the deck and named by it."""
    nml = LEGACY / "earth_mars_team.nml"
    r = fracas("import-namelist", nml, "-o", tmp_path / "t.toml", "--mode", "sweep")
    assert r.exit_code == 2 and "FRACAS has no sweep mode" in r.output
    (tmp_path / "t_traj.toml").write_text("# mine\n", encoding="utf-8")
    r = fracas("import-namelist", nml, "-o", tmp_path / "t.toml")
    assert r.exit_code == 2 and "t_traj.toml: exists; use --force" in r.output
    assert not (tmp_path / "t.toml").exists()
    r = fracas("import-namelist", nml, "-o", tmp_path / "t.toml", "--force")
    assert r.exit_code == 0, r.output
    assert 'deck = "t_traj.toml"' in (tmp_path / "t.toml").read_text()
    r = fracas("import-namelist", nml, "-o", tmp_path / "p.toml", "--mode", "propagate")
    assert r.exit_code == 0, r.output
    assert load_any(tmp_path / "p.toml").mode == "propagate"


def test_output_is_written_atomically(tmp_path, monkeypatch):
    """A failure while the deck is moved into place leaves the old file untouched and no
    temporary file behind (fracas.io.atomic.atomic_path)."""
    import fracas.io.atomic as atomic

    out = tmp_path / "leo.toml"
    out.write_text("# old\n", encoding="utf-8")

    def fail(*_args):
        raise OSError("disk full")

    monkeypatch.setattr(atomic.os, "replace", fail)
    r = fracas("import-namelist", LEGACY / "leo_j2.nml", "-o", out, "--force")
    assert r.exit_code != 0
    assert out.read_text() == "# old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["leo.toml"]


def test_writer_refuses_a_sweep_deck():
    with pytest.raises(DeckError, match="no FRACAS namelist form"):
        namelist_from_deck(load_any(NAMELISTS / "earth_mars_sweep.toml"))


def test_the_config_layer_loads_no_jax(tmp_path):
    """fracas.config.namelist reads and writes decks without importing JAX (import-linter
    contract: config imports no core module)."""
    code = (
        "import json, sys; from fracas.config.namelist import import_namelist, namelist_from_deck; "
        "from fracas.config.tsim import load_tsim_deck; "
        f"import_namelist(namelist_from_deck(load_tsim_deck({str(DATA / 'tsim_small.toml')!r})), 'x.nml'); "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] == 'jax')))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == []


def test_docs_table_names_every_field():
    """docs/namelist.md's mapping table lists every namelist field of the mapping and every
    FRACAS input it reports as having no equivalent."""
    from fracas.config.namelist import KNOWN_UNMAPPED, namelist_fields

    doc = (REPO / "docs" / "namelist.md").read_text(encoding="utf-8")
    for group, fields in namelist_fields().items():
        assert f"### ${group}" in doc
        for f in fields:
            assert re.search(rf"\| `{f.name}(\(|`)", doc), f"{group}.{f.name} is not in docs/namelist.md"
    for group, name in KNOWN_UNMAPPED:
        assert f"`${group}.{name}`" in doc


def test_huge_index_is_refused_in_one_line(tmp_path):
    """TON(3000000) = 1.0, a 40-byte line, used to build three million thrust-arc tables
    (minutes and gigabytes); it is refused naming the variable and the limit."""
    from fracas.config.namelist import MAX_ENTRIES, import_namelist

    p = tmp_path / "big.nml"
    p.write_text("$DATA\n MASS0 = 1000.0\n TON(3000000) = 1.0\n$END\n", encoding="utf-8")
    with pytest.raises(DeckError, match=rf"\$DATA\.TON\(3000000\): index 3000000: expected at most {MAX_ENTRIES}"):
        import_namelist(p, str(p))


# ---------------------------------------------------------------- indices outside an array's range


def _nml_value(f) -> str:
    """A value of the right type for namelist field ``f`` (so that only the index is wrong)."""
    if f.kind == "code":
        return str(f.codes[0][0])
    if f.kind in ("str", "strs", "key", "epoch"):
        return "'EARTH'"
    if f.kind in ("bool", "boolstr"):
        return "T"
    if f.kind == "int":
        return "1"
    return "1.0"


def _indexed_fields():
    """(group, field) for every namelist variable written with an index: entry arrays NAME(k)
    (a "*" in its TOML path), 2-D arrays NAME(j,k) and vectors NAME(j) (reals / strs)."""
    from fracas.config.namelist import namelist_fields

    out = []
    for group, fields in namelist_fields().items():
        for f in fields:
            if f.indexed or f.kind in ("reals", "strs"):
                out.append((group.split()[0], f))
    return out


INDEXED = _indexed_fields()
#: (how the index is written, the index the error names): an index below the first (1), a
#: negative one, a range starting below 1 (which f90nml shifts onto 1..n), more values than
#: the indices written (f90nml drops the extra ones) and an empty range
BAD_INDEX = {
    "zero": ("({j}0) = {v}, {v}, {v}", "({j}0): index 0: expected indices from 1"),
    "zero_single": ("({j}0) = {v}", "({j}0): index 0: expected indices from 1"),
    "negative": ("({j}-2) = {v}", "({j}-2): index -2: expected indices from 1"),
    "range_from_zero": ("({j}0:1) = {v}, {v}", "({j}0): index 0: expected indices from 1"),
    "more_values_than_indices": ("({j}2) = {v}, {v}", "({j}2) = ..., "),
    "empty_range": ("({j}3:2) = {v}", "({j}3:2) = ..., "),
}


@pytest.mark.parametrize("case", sorted(BAD_INDEX))
@pytest.mark.parametrize("group, field", INDEXED, ids=lambda x: getattr(x, "name", x))
def test_an_index_outside_the_array_is_refused(group, field, case):
    """Against the Fortran rule the import documents (arrays indexed from 1, one value per
    index written; f90nml reads an index below 1 as a shift of the start and drops values
    past the last index written): for every indexed namelist variable, such an index is one
    DeckError line naming the file and $GROUP.NAME(index), never a value silently dropped or
    moved."""
    form, named = BAD_INDEX[case]
    two_d = field.indexed and field.kind in ("reals", "strs")
    j = "1," if two_d else ""
    v = _nml_value(field)
    text = f"&{group}\n {field.name}{form.format(j=j, v=v)}\n/\n"
    with pytest.raises(DeckError) as info:
        import_namelist(text, "old.nml")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"old.nml: ${group}.{field.name}{named.format(j=j)}"), (text, msg)


def test_index_zero_of_iatt_is_refused_not_dropped(tmp_path):
    """The case found by the tester: ``IATT(0)=2,2,2`` (f90nml kept one value at a shifted
    start) is one line naming $DATA.IATT(0); the same values written from index 1 import."""
    base = "&DATA EPOCH='2030-01-01', CENTRE='earth', X0=7000,0,0,0,7.5,0, MASS0=1000, TFINAL=1,\n"
    arcs = " TON=0,0.2,0.4, TOFF=0.1,0.3,0.5, POWER0=5, ETA=0.6, ISP=3000,\n"
    with pytest.raises(DeckError, match=r"^old\.nml: \$DATA\.IATT\(0\): index 0: expected indices from 1"):
        import_namelist(base + arcs + " IATT(0)=2,2,2 /\n", "old.nml")
    got = import_namelist(base + arcs + " IATT(1:3)=2,2,2 /\n", "old.nml")
    assert [a["frame"] for a in got.decks["traj"]["thrust_arc"]] == ["inertial"] * 3


def test_a_vector_given_past_its_first_elements_names_the_missing_one():
    """X0(7) = 1.0 leaves X0(1..6) unset: one line naming the first element not given."""
    with pytest.raises(DeckError, match=r"^old\.nml: \$DATA\.X0\(1\): not given; expected a value at every index"):
        import_namelist("&DATA X0(7) = 1.0 /\n", "old.nml")
