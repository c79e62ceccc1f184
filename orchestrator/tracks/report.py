"""What a track's replay prints (``sblsim replay TOA_FILE --format toa``): its lines, and its warnings for standard
error, made from the outcome of :func:`~sblsim.orchestrator.tracks.track.track`; the command prints them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.models.tracking.still_tag import MIN_EXPLAINED
from sblsim.orchestrator.tracks.depth import prior_line
from sblsim.orchestrator.tracks.outcome import ESTIMATOR_NAMES, TrackOutcome
from sblsim.orchestrator.tracks.speed import replaced_line
from sblsim.orchestrator.tracks.tracker import noise_line


def _not_stayed(change: dict) -> str:
    """What a moved tag's console line adds where its second place explains fewer than :data:`MIN_EXPLAINED` of the
    arrivals after the change (it did not stay there: every row after it flagged all the same)."""
    share = change.get("second_place_explained_share")
    if share is None or share >= MIN_EXPLAINED:
        return ""
    return (f" (that place explains {100 * share:.0f} % of the arrivals after the change, fewer than "
            f"{100 * MIN_EXPLAINED:.0f} %: it did not stay there)")


def ping_type_line(summary: dict[str, Any]) -> str:
    """The console's line on the ping type and the gaps of a track's ``summary``."""
    p = summary["ping_type"]
    seen = p["seen"]
    how = "given" if p["source"] == "given" else (
        f"inferred from the first arrivals' spacing: steps of {seen['steps_s'][0]:.4g}-{seen['steps_s'][1]:.4g} s, "
        f"90 % within {seen['spread_s']:.3g} s of a whole number of {seen['typical_step_s']:.4g} s")
    bounds = f" [{p['burst_interval_s'][0]:.4g}, {p['burst_interval_s'][1]:.4g}] s" if p["burst_interval_s"] else ""
    gaps = summary["gaps_s"]
    segments = (f"; {len(gaps)} gap{'s' * (len(gaps) > 1)} (longest {max(gaps):.0f} s): {len(gaps) + 1} track "
                "segments") if gaps else ""
    return f"ping type {p['type']} ({PING_TYPES[p['type']]}{bounds}; {how}){segments}"


def quality_line(summary: dict[str, Any]) -> str:
    """The console's line on the track's quality marks."""
    main = summary["track"]
    flagged = summary["flagged"].get(main, 0)
    n = summary["fixed"].get(main, 0)
    why = ", ".join(f"{name} {count}" for name, count in summary.get("flag_reasons", {}).items())
    return (f"quality: {flagged} of {n} track rows ({ESTIMATOR_NAMES[main]}) flagged"
            f"{f' ({why}: the quality_reason column)' if why else ''}, {summary['restarts']} restarts of the EKF, "
            f"{summary['trusted_fixes']} trusted fixes")



def track_lines(outcome: TrackOutcome, toa: Path, truth: Path | None, kept: Sequence[str] | None, drop: float,
                seed: int, out: Path) -> list[tuple[str, bool]]:
    """The lines ``sblsim replay TOA_FILE --format toa`` prints of a track written to ``out`` (``toa``, ``truth``:
    the files as given; ``kept``, ``drop``, ``seed``: the receivers kept and the detections dropped), in order, each
    with whether it is a warning for standard error."""
    lines: list[tuple[str, bool]] = []

    def say(text: str, warning: bool = False) -> None:
        lines.append((text, warning))

    s = outcome.summary
    c = s["sound_speed"]
    thinned = (f" (kept {len(kept)} of the receivers file's)" if kept is not None else "") + \
        (f", {s['detections_dropped']} detections removed at random ({drop:g}, seed {seed})" if drop else "")
    say(f"track of {toa}: {s['pings']} pings at "
        f"{len(s['receivers'])} receivers{thinned}, sound speed {c['sound_speed_m_s']:.1f} m/s ({c['source']}), "
        f"ping interval {s['ping_interval_s']:.4f} s, in {s['wall_time_s']:.1f} s")
    say("  " + ping_type_line(s))
    aside = s["set_aside"]
    if aside["count"]:
        say(f"  {aside['count']} rows set aside as no pings of the tag's schedule (first arrivals closer than "
            f"{aside['shortest_s']:g} s, less the crossing time, to a row heard by more receivers or as many and "
            "earlier): set_aside.csv, their rows kept in track.csv with no estimate")
    if aside["warning"]:
        say(f"sblsim: warning: {aside['warning']}", True)
    if s.get("two_places"):
        say(f"sblsim: warning: {s['two_places']['warning']}", True)
    say("  " + noise_line(s["toa_noise"]))
    if c["source"] == "fallback":
        say(f"sblsim: warning: the pings do not determine the sound speed ({c['calibration']}); taken: "
            f"{c['method']} (every range scales with it: give --sound-speed, --sound-speed-file or --temperature "
            "with --salinity)", True)
    elif c["source"] == "calibrated with the fallback's prior":
        say(f"sblsim: warning: the pings determine the sound speed only to {c['calibrated_sigma_m_s']:.2g} m/s "
            f"({c['calibrated_m_s']:.1f} m/s); combined with {c['prior']} (± {c['prior_sigma_m_s']:.2g} m/s): "
            f"{c['sound_speed_m_s']:.1f} ± {c['sigma_m_s']:.2g} m/s, the two {c['disagreement_sigmas']:.1f} σ apart "
            "(every range scales with it: give --sound-speed, --sound-speed-file or --temperature with --salinity)",
            True)
    if c.get("disagrees"):
        say(f"sblsim: warning: the sound speed given, {c['sound_speed_m_s']:.1f} m/s, is "
            f"{c['disagreement_sigmas']:.1f} σ from the pings' own calibration ({c['calibrated_m_s']:.1f} ± "
            f"{c['calibrated_sigma_m_s']:.2g} m/s): every range scales with it, by "
            f"{100 * abs(c['sound_speed_m_s'] / c['calibrated_m_s'] - 1):.2g} %; the track takes the speed given", True)
    if replaced_line(c):
        say(f"sblsim: warning: {replaced_line(c)}", True)
    if prior_line(s["depth"]):
        say(f"sblsim: warning: {prior_line(s['depth'])}", True)
    if c.get("pings_outside_series"):
        say(f"sblsim: warning: {c['pings_outside_series']} of {s['pings']} pings lie outside the sound-speed "
            f"series' times [{c['series_time_s'][0]:.10g}, {c['series_time_s'][1]:.10g}] s: their arrivals take "
            "the speed at its nearer end", True)
    m = s["motion"]
    still = m.get("still") or {}
    places = ("one place explains" if still.get("places_explaining", 1) == 1 else
              "two places (one before a change its fixes found, one after) explain")
    explains = (f"{places} {100 * (still.get('explained_share') or 0):.0f} % of its arrivals at the timing "
                f"noise taken, fewer than {100 * MIN_EXPLAINED:.0f} %")
    if still.get("verdict") == "unchecked" and still.get("scattered"):
        say(f"sblsim: warning: whether the tag moved is unchecked: {explains}, and its {still['trusted_fixes']} "
            "trusted single-ping fixes do not tell motion from their errors (it moved, or its timing noise is several "
            "times the one taken: give --toa-sigma); its place takes it as still, every row flagged motion_unchecked",
            True)
    elif still.get("verdict") == "unchecked":
        say(f"sblsim: warning: whether the tag moved is unchecked: {still['trusted_fixes']} trusted single-ping "
            "fixes, too few to test their wander; its place takes it as still, every row flagged motion_unchecked",
            True)
    if m.get("moved"):
        v, change = m["still"], m["still"]["change"]
        beyond = (f"beyond what its error terms let its fixes wander (step statistic {v['step_statistic']:.3g} over "
                  f"{v['threshold']:.3g}; successive fixes {m['moved_test']['successive_ratio']:.2f} of their spread "
                  "apart)")
        if change is None and v.get("scattered"):
            say(f"sblsim: warning: the tag moved the whole time: {explains}, and its {v['trusted_fixes']} trusted "
                "single-ping fixes wander beyond what its error terms allow; every row flagged (track it with "
                "--motion moving)", True)
        elif change is None:
            say(f"sblsim: warning: the tag moved the whole time: its {v['trusted_fixes']} trusted single-ping fixes "
                f"wander {beyond}; every row flagged (track it with --motion moving)", True)
        else:
            split = change.get("split_ping", change["last_still_ping"] + 1)
            how = (f"drifted off after ping {split - 1} (its last still trusted fix; its fixes fit a drift from "
                   "there on, the pings after it flagged)" if change.get("drift") else
                   f"moved after ping {split - 1} (its last still trusted fix at ping {change['last_still_ping']}, "
                   "the pings between given to the place their arrivals fit)")
            say(f"sblsim: warning: the tag {how}: from ping "
                f"{change['first_moved_ping']} on its fixes lie {change['distance_m']:.3g} m from its place, "
                f"{beyond}; its {change['rows_moved']} rows from ping {split} flagged tag_moved and placed where it "
                f"went, the rows before it kept{_not_stayed(change)}", True)
    quality = quality_line(s)
    say("  " + quality)
    for late in s["receivers_late"]:
        say(f"sblsim: warning: receiver {late['receiver']} is out of line of sight: its arrivals are late by "
            f"{late['median_residual_sigmas']:.1f} σ in the median over {late['arrivals']} (the track kept "
            f"{100 * late['kept_share']:.0f} % of them)", True)
    if s["flagged"].get(s["track"]):
        say(f"sblsim: warning: {quality}; see the quality column of track.csv", True)
    names = ESTIMATOR_NAMES
    if outcome.score is not None:
        r = outcome.score
        say(f"  2-D error against {truth} at each estimated emission time [m] (no lag applied):")
        say(f"  {'estimator':<16} {'fixed':>6} {'scored':>6} {'mean':>7} {'median':>7} {'RMS':>8} {'p90':>7} "
            f"{'p95':>7} {'NEES':>7} {'lag [s]':>7}")
        for key, e in [(r["estimator"], r)] + list(r["others"].items()):
            if e.get("median_m") is not None:
                nees = "-" if e["nees"] is None else f"{e['nees']:.3g}"
                lag = "-" if e["lag_s"] is None else f"{e['lag_s']:+.2f}"
                say(f"  {names[key]:<16} {e['n_fixed']:>6} {e['n_scored']:>6} {e['mean_m']:>7.3f} "
                    f"{e['median_m']:>7.3f} {e['rms_m']:>8.3f} {e['p90_m']:>7.3f} {e['p95_m']:>7.3f} {nees:>7} "
                    f"{lag:>7}")
        if not r.get("n_scored"):
            say(f"  no ping inside the truth's times [{outcome.truth[0, 0]:.10g}, {outcome.truth[-1, 0]:.10g}] s: "
                f"none of the {names[r['estimator']]}'s {r['n_fixed']} positions scored")
        if r["nees"] is not None:
            say(f"  NEES of the {names[r['estimator']]} against the truth: mean {r['nees']:.3g}, median "
                f"{r['nees_median']:.3g} (2 and 1.39 when consistent), the truth's own error "
                f"{r['truth_sigma_m']:g} m per axis in the budget (--truth-sigma)")
        if r["lag_s"] is not None:
            say(f"  lag_s {r['lag_s']:+.2f} s: the truth's time shift (searched in ±{r['lag_range_s']:g} s) that "
                f"minimises the {names[r['estimator']]}'s RMS error ({r['rms_at_lag_m']:.3f} m there); reported, "
                "not applied" + (f"; mean error along the truth's heading {r['along_track_m']:+.3f} m, across "
                                 f"{r['across_track_m']:+.3f} m" if "along_track_m" in r else ""))
    else:
        for key, n in s["fixed"].items():
            say(f"  {names[key]}: {n} pings positioned")
    say(f"  written to {out}/ (track.csv, estimates.csv, summary.json, "
        f"{'score.json, errors.csv, bound.csv, ' if outcome.score is not None else ''}track.png)")
    return lines


def tag_line(row: dict[str, Any], count: int, total: int) -> tuple[str, bool]:
    """The line ``sblsim replay FOLDER --format toa`` prints as a tag ends (``row``: its row of ``tags.csv``; the
    ``count``-th of ``total``), with whether it is a warning for standard error (a tag refused)."""
    if row["status"] == "tracked":
        return (f"  [{count}/{total}] {row['tag']}: {row['pings']} pings, {row['positioned']} positioned, "
                f"{row['flagged']} flagged, {row['ping_type']}, {row['wall_time_s']:.1f} s"), False
    return f"sblsim: warning: [{count}/{total}] tag {row['tag']} refused: {row['reason']}", True


def tags_line(table: Any, out: Path) -> str:
    """The last line of ``sblsim replay FOLDER --format toa``: the tags tracked and the rows flagged of ``table``
    (``tags.csv``), written to ``out``."""
    tracked = table[table["status"] == "tracked"]
    return (f"  {len(tracked)} of {len(table)} tags tracked, {int(tracked['flagged'].sum())} of "
            f"{int(tracked['positioned'].sum())} rows flagged; written to {out}/ (tags.csv, one folder per tag)")
