"""The console's lines of a telemetry study (``sblsim track``), made from the study's summary: before its tags are
tracked the detections, the frame, the clocks, the timing noise, the water's depth and the tags; after, each tag's
line, the reference tags' and the sync tags' scores and the closing line.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from sblsim.orchestrator.sync.survey_console import survey_line
from sblsim.orchestrator.tracks.depth import water_line
from sblsim.orchestrator.tracks.speed import REPLACED_SOURCE
from sblsim.orchestrator.tracks.tracker import noise_line


def opening_lines(detections: Path, s: dict[str, Any], count: int, options: dict[str, Any]) -> list[str]:
    """The console's lines before the tracking: the detections, the frame, the clocks, the tags."""
    d, r, c = s["detections"], s["receivers"], s["clocks"]
    why = d["reasons"]
    frame = s["frame"]
    where = (f"frame {frame['name']} ({frame['crs']}, {frame['chosen']}; scale factor "
             f"{frame.get('scale_factor', float('nan')):.5f})") if frame else \
        "a local frame without a CRS (no lat/lon out)"
    out = [f"study of {detections} ({d['format']}): {d['rows']} detections, {d['used']} used at "
           f"{_plural(r['deployments'], 'deployment')} of {_plural(r['receivers'], 'receiver')}, "
           f"{d['set_aside']} set aside ({why['outside_deployment']} "
           f"outside a deployment, {why['receiver_not_in_table']} at serials not in the receivers file, "
           f"{why['sync_tag_outside_deployment']} of sync tags out of the water); {d['first_utc']} to {d['last_utc']}",
           f"  {where}"]
    if c["source"] == "synchronised here":
        out.append(f"  clocks synchronised here against {c['reference_receiver']}: {c['receivers']} receivers, median "
                   f"|residual| {c['median_abs_residual_m']:.3g} m" + (f"; not synchronised: "
                                                                      f"{', '.join(c['not_synchronised'])}"
                                                                      if c["not_synchronised"] else "")
                   + (f"; in {c['windows']['count']} windows of {c['windows']['days']:g} days" if "windows" in c
                      else ""))
        seen = survey_line(c.get("survey_error"), c.get("survey_sigma_m"),
                           "refined" if options.get("refine_positions") else c.get("survey_sigma_from"))
        out.extend([f"  {seen}"] if seen else [])
    elif c["source"] == "given":
        each = c.get("position_sigma_m") if options.get("survey_sigma") is None else None  # (else stated in place)
        out.append(f"  clocks from {c['folder']} ({c['receivers']} receivers, positions {c['positions']})" + (
            f"; the survey error its synchronisation saw taken in every σ: {c['survey_sigma_m']:.3g} m per axis"
            if c.get("survey_sigma_from") == "seen" else "") + (
            f"; each position's error in every σ: {min(each.values()):.3g} to {max(each.values()):.3g} m per axis"
            if each else ""))
    elif "one receiver" in c["source"]:
        out.append("  clock taken as logged (one receiver: no other to synchronise it against)")
    elif "too coarse" in c["source"]:
        out.append("  clocks taken as logged: the sync tags' times are rounded too coarsely to synchronise them "
                   "(the note below)")
    elif c["source"] == "fitted from the tags' pings":  # (study_offsets.FITTED: numpy, loaded with the study)
        out.append(f"  clocks fitted from {len(c['tags'])} moving tags' {c['pings']:,} pings against "
                   f"{c['reference_receiver']} ({c['receivers']} receivers; taken as logged, "
                   + ("no sync tag heard by two receivers" if "heard" in c["as_logged"]["source"] else
                      "no sync tag in the receivers file") + f", they were off by up to {c['largest_offset_s']:.3g} s)"
                   + (f"; not synchronised: {len(c['not_synchronised'])} ({', '.join(c['not_synchronised'][:8])}"
                      + (", ...)" if len(c["not_synchronised"]) > 8 else ")") if c["not_synchronised"] else ""))
    else:
        checked = c.get("checked") or {}
        held = checked.get("held_out")
        out.append("  clocks taken as logged (" + ("no sync tag heard by two receivers" if "heard" in c["source"]
                                                   else "no sync tag in the receivers file") + "): " + (
            f"the moving tags' pings left out fit them as well as clocks fitted from the others (chi2 per degree of "
            f"freedom {held['logged_chi2_per_dof']:.3g} as logged, {held['fitted_chi2_per_dof']:.3g} fitted)" if held
            else f"not checked against the tags' pings ({checked['reason']})" if checked.get("reason") else
            "not checked against the tags' pings"))
    if "toa_noise" in s:
        out.append("  " + noise_line(s["toa_noise"]))
    if s.get("water_depth"):
        out.append("  " + water_line(s["water_depth"]))
    where = "on " + options["scheduler"] if options["scheduler"] else \
        f"in {min(options['workers'] or os.cpu_count() or 1, max(count, 1))} worker processes"
    out.append(f"  tracking {count} tags {where}")
    return out


#: The refused tags the console names one by one (the others counted by reason; every one is a row of tags.csv).
MAX_REFUSED_LINES = 10


def _plural(n: int, word: str) -> str:
    """``1 ping``, ``1,204 pings``: a count as a count."""
    return f"{int(n):,} {word}{'' if int(n) == 1 else 's'}"


def tag_line(row: Any) -> str:
    """The console's line of a tracked tag (``row``: its row of ``tags.csv``): its pings positioned, set aside and
    not positioned, the rows flagged, the median σ of the rows not flagged, the ping type and sound speed taken,
    its first and last row's time."""
    aside = f"{int(row.set_aside):,} set aside (set_aside.csv), " if row.set_aside else ""
    unplaced = f"{int(row.not_positioned):,} not positioned ({row.not_positioned_why}), " if row.not_positioned else ""
    sigma = f"median σ {row.median_sigma_m:.2g} m" if row.median_sigma_m == row.median_sigma_m else \
        "every row flagged: no median σ"
    span = f", {row.first_utc} to {row.last_utc}" if row.first_utc and row.last_utc else ""
    return (f"  {row.tag}: {_plural(row.pings, 'ping')}, {int(row.positioned):,} positioned, {aside}{unplaced}"
            f"{int(row.flagged):,} flagged, {sigma}, ping type {row.ping_type} (the sheet: {row.ping_type_stated}), "
            f"sound speed {row.sound_speed_m_s:.1f} m/s ({row.sound_speed_source}){span}")


def tag_lines(table: Any) -> list[tuple[str, bool]]:
    """The console's lines of a study's tags (``table``: ``tags.csv``), each with whether it is a warning for
    standard error: a line per tracked tag (:func:`tag_line`), a warning per refused tag (its reason), the
    :data:`MAX_REFUSED_LINES` with the most detections, the others counted by ``reason_code``."""
    lines: list[tuple[str, bool]] = []
    refused = table[table["status"] != "tracked"].sort_values("detections", ascending=False, kind="stable")
    for row in table.itertuples(index=False):
        if row.status == "tracked":
            lines.append((tag_line(row), False))
            second = getattr(row, "two_places", "")  # a second place heard at once: its rows flagged
            if isinstance(second, str) and second:
                lines.append((f"sblsim: warning: tag {row.tag}: {second}", True))
            if row.sound_speed_source in ("fallback", REPLACED_SOURCE):  # never taken without a word
                lines.append((f"sblsim: warning: tag {row.tag}: the pings do not determine the sound speed "
                              f"({row.sound_speed_source}); taken: {row.sound_speed_m_s:.1f} m/s, every range scales "
                              "with it: give --sound-speed, --sound-speed-file or --temperature with --salinity",
                              True))
    for row in refused.head(MAX_REFUSED_LINES).itertuples(index=False):
        lines.append((f"sblsim: warning: tag {row.transmitter} not tracked ({row.reason_code}): {row.reason}", True))
    rest = refused.iloc[MAX_REFUSED_LINES:]
    if len(rest):
        codes = ", ".join(f"{code} {n:,}" for code, n in rest["reason_code"].value_counts().items())
        lines.append((f"sblsim: warning: {_plural(len(rest), 'more tag')} not tracked ({codes}): their reasons are "
                      "in tags.csv (reason_code, reason)", True))
    return lines


def _nees(pooled: dict[str, Any]) -> str:
    """A pooled NEES and the interval in which 90 % of such means lie where the σ holds, as the console says it."""
    if pooled.get("nees_mean") is None:
        return "no NEES"
    low, high = pooled["nees_consistent_90"]
    return f"NEES {pooled['nees_mean']:.2g} ({low:.2g} to {high:.2g} in 90 % of studies whose σ holds)"


def reference_lines(scored: dict[str, Any] | None) -> list[tuple[str, bool]]:
    """The console's lines of a study's reference tags and sync tags left out in turn (``scored``: ``study.json``'s
    ``reference_tags``, :mod:`.reference_tags`), each with whether it is for standard error: one line each, pooled,
    and one of both kinds pooled; a warning per still tag beyond its σ; a note per reference tag not scored."""
    if not scored:
        return []
    out: list[tuple[str, bool]] = []
    ref, loo, both = scored["reference"], scored["sync_left_out"], scored.get("still")
    if ref is not None:
        exact = "" if ref["survey_stated"] == ref["tags"] else \
            f", {ref['tags'] - ref['survey_stated']} of {ref['tags']} positions taken as exact (no survey_sigma_m)"
        out.append((f"  reference tags: {ref['tags']}, median error {ref['median_error_m']:.2g} m, {_nees(ref)}, "
                    f"{ref['flagged']:,} of the {_plural(ref['rows'], 'row')} flagged (σ: each place's covariance as "
                    f"tracked{exact})", False))
    if loo is not None and loo.get("placed"):
        fixes = "" if loo["placed"] == loo["tags"] else \
            f"; {loo['tags'] - loo['placed']} by their single-emission fixes, no place fitted"
        out.append((f"  sync tags left out in turn (each one place, as a reference tag): {loo['tags']}, median error "
                    f"{loo['median_error_m']:.2g} m, {_nees(loo)}, {loo['flagged']:,} of the "
                    f"{_plural(loo['rows'], 'emission')} flagged{fixes}", False))
    elif loo is not None:
        inside = "" if loo["nees_mean_inside"] is None else \
            f", NEES {loo['nees_mean_inside']:.3g} inside the array ({loo['inside']})"
        out.append((f"  sync tags left out in turn (their single-emission fixes): {loo['tags']}, median error "
                    f"{loo['median_error_m']:.3g} m{inside}, {loo['without_fix']:,} of "
                    f"{_plural(loo['emissions'], 'emission')} without a trusted fix", False))
    if both is not None:
        out.append((f"  still tags together (reference and sync left out): {both['tags']}, median error "
                    f"{both['median_error_m']:.2g} m, {_nees(both)}", False))
    array = scored.get("array_persistent_m")
    for row in scored["tags"]:
        if not row["beyond_sigma"]:
            continue
        if row["kind"] != "reference":
            out.append((f"sblsim: warning: sync tag {row['tag']}, left out, is {row['error_m']:.3g} m from its "
                        f"receiver {row['receiver']}'s position, NEES {row['nees']:.3g} beyond its σ of "
                        f"{row['sigma_m']:.2g} m (χ²(2)'s 99 %: {loo['beyond_nees']:.3g}): the receiver's "
                        "position is wrong, or the tag hangs away from it", True))
            continue
        kept = row["receiver_persistent_m"]
        sync = "" if kept is None or kept != kept else \
            (f"; the synchronisation's residuals at {row['receiver']} keep {kept:.2g} m its clock does not explain"
             + ("" if array is None else f" (the array's median {array:.2g} m)"))
        out.append((f"sblsim: warning: reference tag {row['tag']} is {row['error_m']:.3g} m from {row['truth']}, NEES "
                    f"{row['nees']:.3g} beyond its σ of {row['sigma_m']:.2g} m (χ²(2)'s 99 %: "
                    f"{scored['reference']['beyond_nees']:.3g}): the tag moved, its position is wrong, or a receiver's "
                    f"is{sync}", True))
    for entry in scored["not_scored"]:
        out.append((f"note: reference tag {entry['tag']} not scored: {entry['why']}", True))
    for note in scored.get("notes", []):
        out.append((f"note: {note}", True))
    return out


def closing_line(table: Any, seconds: float, out: Path, files: str) -> str:
    """The console's last line: the tags tracked and refused by reason (``table``: ``tags.csv``), their rows
    positioned and flagged, the time, and the files written to ``out`` (``files``: their names)."""
    tracked = table[table["status"] == "tracked"]
    codes = table.loc[table["status"] != "tracked", "reason_code"].value_counts()
    why = f" (not tracked: {', '.join(f'{code} {n:,}' for code, n in codes.items())})" if len(codes) else ""
    rows = f", {int(tracked['flagged'].sum()):,} of the {_plural(tracked['positioned'].sum(), 'row')} positioned " \
        "flagged" if len(tracked) else ""
    return f"  {int(len(tracked)):,} of {_plural(len(table), 'tag')} tracked{why}{rows}, in {seconds:.1f} s; " \
        f"written to {out}/ ({files})"


def study_lines(outcome: Any) -> list[tuple[str, bool]]:
    """The console's lines of a study once it has run, each with whether it is for standard error: the clocks' fit
    from the tags' pings where it leaves more than the noise (:func:`~.study_offsets.misfit`), the tags kept
    from an interrupted run (:mod:`~sblsim.orchestrator.tracks.resume`), its tags' (:func:`tag_lines`), its
    reference tags' (:func:`reference_lines`) and its refined positions'
    (:func:`~sblsim.orchestrator.telemetry.study_positions.lines`)."""
    from sblsim.orchestrator.telemetry.study_offsets import misfit  # numpy and pandas: loaded with the study
    from sblsim.orchestrator.telemetry.study_positions import lines

    resumed = outcome.summary.get("resumed")
    kept = []
    unheld = misfit(outcome.summary)
    if unheld:
        kept.append((f"sblsim: warning: {unheld}", True))
    if resumed:
        what = " and ".join([f"{resumed['tags_kept']} of {resumed['tags']} tags"] + resumed["taken"])
        kept.append((f"resumed: {what} kept from an interrupted run of this output (their inputs unchanged)", False))
    return (kept + tag_lines(outcome.tags) + reference_lines(outcome.summary.get("reference_tags"))
            + lines(outcome.summary.get("positions")))


__all__ = ["MAX_REFUSED_LINES", "closing_line", "opening_lines", "reference_lines", "study_lines", "tag_line",
           "tag_lines"]
