"""The exchange-file commands: ``fracas export`` (CCSDS OEM/OPM, covariance CSV),
``fracas compare-oem`` and ``fracas import-namelist`` (legacy FRACAS NAMELIST decks)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import click

from fracas.cli.console import InputFile, OutputFile, _error_line, _errors, _say


@click.command()
@click.argument("file", type=InputFile())
@click.option("--oem", "oem_out", type=OutputFile("OEM"), help="Write a CCSDS OEM.")
@click.option(
    "--team",
    "team_file",
    type=InputFile(),
    help="With a trajectory FILE: a TEAM results file whose covariances go into the OEM.",
)
@click.option(
    "--covariance",
    type=click.Choice(["true", "assumed", "none"]),
    default=None,
    help="Which knowledge covariance (default: true when the file has it, else assumed; none: states only).",
)
@click.option("--before-update", is_flag=True, help="The covariance before each event's update (P-), not after.")
@click.option(
    "--covariance-at",
    "events",
    multiple=True,
    metavar="EVENT_OR_TIME",
    help="TEAM events for --opm/--csv: an event name (final, eigenvector, ...), days from the epoch, "
    "an ISO TDB epoch, #index or all (repeatable).",
)
@click.option("--opm", "opm_out", type=OutputFile("OPM"), help="Write CCSDS OPM(s).")
@click.option("--csv", "csv_out", type=OutputFile("CSV"), help="Write the covariances as CSV.")
@click.option("--xml", is_flag=True, help="OEM/OPM in XML instead of KVN.")
@click.option("--object-name", default=None, help="OBJECT_NAME (default: the file's title).")
@click.option("--object-id", default="UNKNOWN", show_default=True, help="OBJECT_ID.")
@click.option("--originator", default="FRACAS", show_default=True, help="ORIGINATOR.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def export(
    ctx: click.Context,
    file: Path,
    oem_out: Path | None,
    team_file: Path | None,
    covariance: str | None,
    before_update: bool,
    events: tuple[str, ...],
    opm_out: Path | None,
    csv_out: Path | None,
    xml: bool,
    object_name: str | None,
    object_id: str,
    originator: str,
    debug: bool,
) -> None:
    """Export FILE (a trajectory or TEAM results file) as CCSDS exchange files (docs/exchange.md):
    --oem a trajectory with covariances; --covariance-at EVENT with --opm and/or --csv the
    covariances of chosen TEAM events."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        from fracas.io import ccsds

        _check_export(file, oem_out, opm_out, csv_out, events, team_file)
        entries, team = _covariance_entries(file, events, covariance, before_update)
        if oem_out is not None:
            ccsds.write_oem(
                oem_out,
                file,
                team=team_file,
                covariance=covariance,
                before_update=before_update,
                xml=xml,
                object_name=object_name,
                object_id=object_id,
                originator=originator,
            )
            _say(f"written: {oem_out}")
        if entries:
            name = object_name or str(team["attrs"].get("title", "")) or "SPACECRAFT"
            _write_covariances(file, entries, opm_out, csv_out, xml, name, object_id, originator)


def _check_export(
    file: Path,
    oem_out: Path | None,
    opm_out: Path | None,
    csv_out: Path | None,
    events: tuple[str, ...],
    team_file: Path | None = None,
) -> None:
    """What ``fracas export`` was asked is coherent, and every output can be written."""
    from fracas.errors import FracasError
    from fracas.io.atomic import check_output_path

    if oem_out is None and opm_out is None and csv_out is None:
        raise FracasError(f"{file}: nothing to export: give --oem, --opm or --csv")
    if (opm_out is not None or csv_out is not None) and not events:
        raise FracasError(f"{file}: --opm and --csv need --covariance-at EVENT_OR_TIME (e.g. final, all)")
    if events and opm_out is None and csv_out is None:
        raise FracasError(f"{file}: --covariance-at is for --opm or --csv")
    for out, what in ((oem_out, "OEM"), (opm_out, "OPM"), (csv_out, "CSV")):
        if out is not None:
            check_output_path(out, what, (file, team_file))


def _covariance_entries(
    file: Path, events: tuple[str, ...], covariance: str | None, before_update: bool
) -> tuple[list[dict[str, Any]], Any]:
    """(the covariances at the chosen TEAM events, the TEAM results) -- everything checked and
    selected before any file is written; ([], None) without --covariance-at."""
    from fracas.errors import FracasError
    from fracas.io import ccsds

    if not events:
        return [], None
    if ccsds.file_kind(file) != "team":
        raise FracasError(f"{file}: --covariance-at needs a TEAM results file")
    if covariance == "none":
        raise FracasError(f"{file}: --covariance none: --opm and --csv write covariances")
    from fracas.io.team_results import read_team_results

    team = read_team_results(file)
    picked = ccsds.select_events(team, list(events))
    return [ccsds.covariance_at(team, k, covariance, before_update) for k in picked], team


def _write_covariances(
    file: Path,
    entries: list[dict[str, Any]],
    opm_out: Path | None,
    csv_out: Path | None,
    xml: bool,
    name: str,
    object_id: str,
    originator: str,
) -> None:
    """An OPM per event (numbered when several) and/or one covariance CSV."""
    from fracas.io import ccsds

    if opm_out is not None:
        for c in entries:
            out = opm_out
            if len(entries) > 1:
                out = opm_out.with_name(f"{opm_out.stem}_{c['index']:04d}{opm_out.suffix}")
            ccsds.write_opm(
                out, c, xml=xml, object_name=name, object_id=object_id, originator=originator, source=file.name
            )
            _say(f"written: {out} (event #{c['index']} {c['event']})")
    if csv_out is not None:
        ccsds.write_covariance_csv(csv_out, entries)
        _say(f"written: {csv_out} ({len(entries)} events x {len(entries[0]['labels'])} labels)")


@click.command("compare-oem")
@click.argument("trajectory", type=InputFile())
@click.argument("oem_file", metavar="FILE.oem", type=InputFile())
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary instead of the table.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def compare_oem(ctx: click.Context, trajectory: Path, oem_file: Path, as_json: bool, debug: bool) -> None:
    """Position/velocity differences (fracas - OEM) between a TRAJECTORY file and an OEM at
    their common epochs (within 1 µs, same centre)."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        import numpy as np

        from fracas.io.ccsds import compare_oem as compare
        from fracas.timescales import et_to_calendar

        d = compare(trajectory, oem_file)
        dr = np.linalg.norm(d["dr_km"], axis=1)
        dv = np.linalg.norm(d["dv_km_s"], axis=1)
        summary = {
            "trajectory": str(trajectory),
            "oem": str(oem_file),
            "common_epochs": int(dr.size),
            "trajectory_epochs": d["n_trajectory"],
            "oem_epochs": d["n_oem"],
            "other_centre": d["other_centre"],
            "max_dr_km": float(dr.max()),
            "rms_dr_km": float(np.sqrt(np.mean(dr**2))),
            "max_dv_km_s": float(dv.max()),
            "rms_dv_km_s": float(np.sqrt(np.mean(dv**2))),
        }
        if as_json:
            click.echo(json.dumps(summary))
            return
        click.echo(f"{'epoch (TDB)':<27} {'t (d)':>10} {'centre':<8} {'|dr| km':>12} {'|dv| km/s':>12}")
        for k in range(dr.size):
            click.echo(
                f"{et_to_calendar(d['et_s'][k], 6):<27} {d['t_s'][k] / 86400.0:>10.5f} {d['centre'][k]:<8} "
                f"{dr[k]:>12.4e} {dv[k]:>12.4e}"
            )
        _say(
            f"{dr.size} common epochs ({d['n_trajectory']} in the trajectory, {d['n_oem']} in the OEM"
            + (f", {d['other_centre']} with another centre" if d["other_centre"] else "")
            + f"): max |dr| {summary['max_dr_km']:.4e} km, RMS {summary['rms_dr_km']:.4e} km; "
            f"max |dv| {summary['max_dv_km_s']:.4e} km/s, RMS {summary['rms_dv_km_s']:.4e} km/s"
        )


@click.command("import-namelist")
@click.argument("namelist", type=InputFile())
@click.option(
    "-o",
    "--output",
    required=True,
    type=OutputFile("TOML deck"),
    help="TOML deck to write (sub-decks it names are written beside it).",
)
@click.option(
    "--mode",
    type=click.Choice(["propagate", "tom", "team", "tsim", "sweep"]),
    default=None,
    help="Read the deck as this mode (default: the deck's mode label, else its namelists).",
)
@click.option("--force", is_flag=True, help="Overwrite output decks that exist.")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.pass_context
def import_namelist_command(
    ctx: click.Context, namelist: Path, output: Path, mode: str | None, force: bool, debug: bool
) -> None:
    """Import a legacy FRACAS NAMELIST deck ($DATA, $ERTRAJ, $INSIM, ...) as a TOML deck; every
    field that could not be mapped is listed (docs/namelist.md)."""
    debug = debug or bool((ctx.obj or {}).get("debug"))
    with _errors(debug):
        import textwrap

        from fracas.config.namelist import import_namelist
        from fracas.errors import OutputPathError
        from fracas.io.atomic import atomic_path, check_output_path

        out = check_output_path(output, "TOML deck", (namelist,))
        result = import_namelist(namelist, str(namelist), mode=mode, name=out.stem)
        files = {out: result.toml, **{out.parent / name: text for name, text in result.companions.items()}}
        for path in files:
            check_output_path(path, "TOML deck", (namelist,))
            if path.exists() and not force:
                raise OutputPathError(f"{path}: exists; use --force to overwrite it")
        for path, text in files.items():
            with atomic_path(path) as tmp:
                tmp.write_text(text, encoding="utf-8")

        def say(text: str, indent: str = "") -> None:
            click.echo(
                textwrap.fill(
                    text,
                    80,
                    initial_indent=indent,
                    subsequent_indent=indent + "    ",
                    break_long_words=False,
                    break_on_hyphens=False,
                )
            )

        n_un = len(result.unmapped)
        say(f"imported {namelist} -> {out} ({result.mode} mode): {result.mapped} field(s) mapped, {n_un} not mapped")
        for path in list(files)[1:]:
            say(f"also written: {path}")
        if result.unmapped:
            click.echo("not mapped:")
            for u in result.unmapped:
                say(str(u), "  ")
        if result.notes:
            click.echo("notes:")
            for note in result.notes:
                say(note, "  ")
        from fracas.modes import check_path

        _, problems = check_path(out)
        for line in problems:
            _error_line(f"fracas: error: {line}")
        if problems:
            sys.exit(2)
        say(f"ok: {out} validates")
