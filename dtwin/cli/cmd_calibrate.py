"""``dtwin calibrate BASELINE... --spec SPEC --out DIR``: fit what the gearbox does not publish
(window shape, mesh excitation, mesh damping, sensor frequency response) from healthy records
and write a calibrated spec that every command accepts (:mod:`dtwin.identify.calibrate`).

The folder holds ``calibrated.toml`` (the user's spec plus the fitted fields and a
``[calibration]`` table), ``calibration.json`` (parameters with standard deviations and the
"determined" flag, the gap per band before, cross-validated and confirmed), the figures
``calibration_spectra.png`` and ``calibration_gap.png``, the spectra as CSV/NPZ, a
``report.html`` and the manifest. The user's spec file is never modified.
"""

from __future__ import annotations

from pathlib import Path

import typer

from ..signal.units import unit_name
from . import options as opts
from .app import app


def _channel_index(record, channel: str | int) -> int:
    if isinstance(channel, int):
        return channel
    return list(record.channels).index(channel)


#: Most knots `--knots` accepts (the sensor response is smooth; each knot is one fitted gain).
MAX_KNOTS = 40


@app.command()
def calibrate(
    records: list[Path] = typer.Argument(..., help="Healthy record file(s) of the machine."),
    spec: Path | None = opts.spec_option("The user's gearbox spec (TOML); never modified."),
    preset: str | None = opts.preset_option(),
    model: str | None = typer.Option(None, "--model", help="torsional or translational twin "
                                     "(default: the spec's model.kind)."),
    knots: int = typer.Option(5, "--knots", parser=opts.whole_number,
                              help="Knots of the sensor frequency response."),
    window_terms: int | None = typer.Option(
        None, "--window-terms", parser=opts.whole_number,
        help="Cosine terms of the planet-angle window (default: 2 N + 1 for N planets, the "
             "window's harmonics up to the second planet pass 2 N f_carrier)."),
    mesh_harmonics: int | None = typer.Option(
        None, "--mesh-harmonics", parser=opts.whole_number,
        help="Mesh harmonics with a fitted transmission error (default: every one below 0.45 × "
             "the rate, at most 12)."),
    load_sharing: str = typer.Option("auto", "--load-sharing",
                                     help="Fit the planets' load shares: auto (when the records "
                                          "show carrier orders equal sharing cannot make), on, "
                                          "off."),
    f_sun: float | None = opts.f_sun_option("Input (sun) speed of the records in Hz; "),
    tacho: str | None = opts.tacho_option(),
    channel: str = opts.channel_option(),
    sample_rate: float | None = opts.sample_rate_option(),
    json_out: bool = opts.json_option(),
    out: Path | None = opts.out_option("calibrated.toml, calibration.json, figures, report.html",
                                       required=True),
    force: bool = opts.force_option(),
) -> None:
    """Calibrate the twin on healthy records and write a calibrated spec (see docs/calibration.md)."""
    from dtwin.identify.calibrate import CalibrationSettings
    from dtwin.identify.calibrate import calibrate as run
    from dtwin.model.registry import N_EXCITATION_HARMONICS, N_WINDOW_TERMS

    if model is not None:
        opts.choice("--model", model, ("torsional", "translational"))
    opts.count("--knots", knots, 1, MAX_KNOTS,  # each knot one fitted gain, seen by its lines
               "the knots are log-spaced from 0.8 N f_carrier to the passband, each a gain the "
               "mesh lines next to it must determine (and each a column of every record's "
               "Jacobian in memory)")
    opts.count("--window-terms", window_terms, 2, N_WINDOW_TERMS,
               "the window terms with a registry name")
    opts.count("--mesh-harmonics", mesh_harmonics, 1, N_EXCITATION_HARMONICS,
               "the excitation harmonics with a registry name")
    opts.choice("--load-sharing", load_sharing, ("auto", "on", "off"))
    opts.input_speed_option("--f-sun", f_sun)
    opts.tacho_reading(tacho)
    opts.check_out(out, force)
    gb = opts.load_gearbox(preset, spec)
    ch = opts.channel_token(channel)
    recs = []
    for p in records:
        r = opts.read_record(p, sample_rate, tacho)
        opts.check_channel(r, ch)
        opts.check_fit_memory(r, gb.spec, p, command="calibrate", records=recs)
        opts.checked_record(r, ch, gb.spec, f_sun, fit=True)
        opts.check_speed_against_lines(r, gb.spec, f_sun, ch, p)
        r.metadata["source"] = p.name
        recs.append(r)
    settings = CalibrationSettings(window_terms=window_terms, n_knots=knots,
                                   load_sharing=load_sharing, mesh_harmonics=mesh_harmonics)
    import logging

    from .progress import progress, record_size

    log = logging.getLogger("dtwin")
    with progress("calibrate", json_out=json_out, size=record_size(recs[0])) as stage:
        result = run(recs, gb.spec, kind=model, f_sun=f_sun, channel=_channel_index(recs[0], ch),
                     settings=settings, progress=stage)
    report = result.to_dict()
    report["spec"] = gb.source
    if not result.improves:
        log.warning("the calibrated values are not adopted (%s): the calibrated spec keeps the "
                    "spec's own values with its fitted response level. Either the spec already "
                    "describes these records, or they hold lines the calibrated parameters "
                    "cannot represent (run dtwin discover on them)", result.rejection)
    if result.departs:
        log.warning("the calibrated twin simulated in full departs from the fit's linearised "
                    "response by %.1f dB after %d linearisation(s): the calibrated excitation or "
                    "load shares lie beyond first order (contact loss?); the confirmed gap, "
                    "not the held-out one, is the twin's (docs/calibration.md)",
                    result.departure_db, result.linearisations)
    if result.teeth_part:
        log.warning("the calibrated twin's teeth part every mesh cycle (least mesh deflection "
                    "%.2f of its mean): its excitation exceeds the static deflection under the "
                    "load, and the clipped contact makes mesh harmonics and aliases that move "
                    "with the speed, so records at another speed will not fit "
                    "(docs/calibration.md, 'Teeth that part')", result.contact_margin)
    if not result.fit_converged:
        log.warning("calibration's final fit %s", result.fit_status)
    unit = unit_name(recs[0].units[_channel_index(recs[0], ch)])
    opts.emit(report, json_out=json_out, table=lambda: typer.echo(result.table()), out=out,
              force=force, files=_files(result, report, unit), inputs=[spec, *records],
              gearbox=gb, parameters={"records": [str(p) for p in records], "knots": knots,
                                      "window_terms": window_terms,
                                      "mesh_harmonics": mesh_harmonics, "model": model,
                                      "f_sun": f_sun, "tacho": tacho})


def _files(result, report, unit: str):
    def files() -> dict:
        from dtwin.identify.plotting.calibrate import (
            plot_calibration_gap,
            plot_calibration_spectra,
        )
        from dtwin.spec.writer import spec_to_toml

        from ..io.export import Columns
        from ..report.html_report import HTMLReport, frequency_text

        # a frequency (Hz) to 0.01 Hz, other values to 5 significant digits
        rows = [{"parameter": p.name, "value": (frequency_text(p.value) if p.unit == "Hz"
                                                else f"{p.value:.5g}"), "sd": f"{p.sd:.2g}",
                 "unit": p.unit, "status": p.status,
                 "note": p.note} for p in result.parameters]
        return {
            "calibrated.toml": spec_to_toml(result.spec_data),
            "calibration.json": report,
            "calibration_spectra.png": plot_calibration_spectra(result, unit),
            "calibration_gap.png": plot_calibration_gap(result),
            "calibration_spectra.csv": Columns(
                {"frequency": result.freqs, "measured": result.a_meas[0],
                 "spec_as_written": result.a_before[0], "calibrated": result.a_after[0]},
                {"frequency": "Hz", "measured": unit, "spec_as_written": unit,
                 "calibrated": unit}),
            "report.html": HTMLReport(
                title=f"dtwin calibrate: {', '.join(result.records)}",
                summary={"records": ", ".join(result.records), "speed (Hz)": result.f_sun,
                         "gap before (dB)": round(result.gap_before.total, 2),
                         "held-out gap, cross-validated (dB)":
                             round(result.gap_heldout.total, 2),
                         "gap of the calibrated twin, full simulation (dB)":
                             round(result.gap_confirmed.total, 2),
                         "noise floor rms": result.noise_rms,
                         "final fit": result.fit_status},
                figures={"Measured vs twin, before and after": "calibration_spectra.png",
                         "Gap per band": "calibration_gap.png"},
                tables={"Calibrated parameters": rows},
                notes=[f"{n}: not determined by these records"
                       for n in result.not_determined]
                + [f"{p.name}: {p.status}" for p in result.parameters
                   if not p.determined and p.joint_with]),
        }

    return files
