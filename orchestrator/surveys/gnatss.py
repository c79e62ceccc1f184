"""Read a GNATSS GNSS-Acoustic survey (``pxp_tt`` + ``POS_FREED_TRANS_TWTT`` + the site) into the calibration log.

GNATSS (the community GNSS-Acoustic software, seafloor-geodesy/gnatss) takes a survey as three inputs;
this module reads them as GNATSS documents and uses them (its ``docs/input.md``, ``gnatss/loaders.py``,
``gnatss/ops/data.py`` and ``gnatss/configs/`` at commit 44ca5389):

``pxp_tt``
    One line per interrogation (ping): the date and time of transmission (``27-JUL-22 17:37:45.00``, UTC),
    then one two-way travel time per transponder in microseconds, in the order of the site's transponders
    (a ``0`` is a missing reply), then columns GNATSS ignores. Each travel time includes that transponder's
    turnaround (internal delay): 0.20, 0.32 and 0.44 s at NCL1, so that replies only 0.12 s apart arrive in
    another order than the transponders' when the slant ranges differ. A reply is therefore paired with its
    transponder by its column (its identity), never by the order of arrival.
``POS_FREED_TRANS_TWTT``
    The surface transducer's position, one line per epoch: the time in seconds since J2000
    (2000-01-01T12:00:00, counted without leap seconds, like POSIX time), the ECEF x, y, z [m] and the
    ECEF covariance [m^2] as 9 numbers row by row (xx, xy, xz, yx, yy, yz, zx, zy, zz). There is a line
    at each transmission and at each reply's arrival, ``t_tx + TWTT`` (the turnaround included). A line is
    found by its time, not by its place in the file.
The site (:mod:`.gnatss_site`, a small TOML file of ours, ``data/ncl1/site.toml`` for NCL1)
    The array centre (the local frame's origin), the transponders' a-priori latitude, longitude and
    orthometric height (GNATSS's ``height``, above the geoid: the ellipsoidal height is
    ``height + geoid_undulation``, as GNATSS's solver takes it), their turnarounds and their column in
    ``pxp_tt``, the start depth of the harmonic mean and the editing limits.

The log (one row per reply, the columns :data:`LOG_COLUMNS`) is in local east/north/up [m] at the array
centre (pymap3d's ECEF -> ENU on WGS84); the 1-sigma of each coordinate is the square root of the
diagonal of the covariance rotated to ENU (``R C Rᵀ``, R the ECEF -> ENU rotation at the array centre,
found by rotating the unit vectors with pymap3d). Times are POSIX seconds, UTC: the ``pxp_tt`` time is UTC
(GNATSS's ``docs/input.md``) and its J2000 seconds are ``POSIX − 946728000``, which the reader checks
against the transmit line of ``POS_FREED_TRANS_TWTT``. ``twtt_s`` is the travel time less the
transponder's turnaround (GNATSS's transducer delay and travel-time correction are 0 for NCL1).

:func:`community_editing` keeps the pings the community keeps at a site (every transponder replied, the 3-D
GNSS sigma of the transmit and every receive position at most ``gnss_sigma_limit_m``, the transmit point
within ``distance_limit_m`` of the array centre, horizontally). :func:`straight_ray_residuals` checks the
reading against the a-priori positions (or shifted ones) at each transponder's harmonic-mean sound speed of the
CTD. The survey is solved by the calibration solver (:mod:`sblsim.models.calibration`; the built-in survey
``ncl1-2022-208`` of ``sblsim calibrate``).

Every file is read as hostile (the helpers every log reader shares, :mod:`sblsim.orchestrator.io.tables`): a
regular file of ASCII text only, within the logs' documented size, every number checked with its file, line
and column named (:class:`~sblsim.models.errors.ModelError`, one line). No file names another file the reader opens.
The two files are read by :mod:`.gnatss_files`, the site by :mod:`.gnatss_site`; the local frame is
:mod:`.local_frame`'s and the harmonic means :mod:`.harmonic_mean`'s. This module joins them into the log.

References
----------
GNATSS, GNSS-Acoustic Seafloor Positioning Software, https://github.com/seafloor-geodesy/gnatss (BSD-3).
Chadwell, C. D., and Sweeney, A. D. (2010), Acoustic ray-trace equations for seafloor geodesy, Marine
Geodesy 33(2-3), 164-186 (the straight ray at the harmonic-mean speed).
IOGP, Geomatics Guidance Note 7-2, method 9836 (geocentric/topocentric conversions: the ENU rotation).
"""

from __future__ import annotations

import argparse
import sys
from importlib import resources
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sblsim.models.errors import ModelError
from sblsim.orchestrator.io.output import write_atomic
from sblsim.orchestrator.surveys.gnatss_files import J2000_POSIX, read_posfilter, read_pxp_tt
from sblsim.orchestrator.surveys.gnatss_site import Site, _near_origin, read_site
from sblsim.orchestrator.surveys.local_frame import ecef_to_enu, enu_rotation
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, POSITION_RANGE

#: The vendored NCL1 data (orchestrator/surveys/data/ncl1/).
DATA = ("sblsim.orchestrator.surveys", "data/ncl1")


def read_gnatss(pxp_tt: Path | str, posfilter: Path | str, site: Site | Path | str) -> tuple[pd.DataFrame, Site]:
    """Read a GNATSS survey into the calibration log: one row per reply.

    Parameters
    ----------
    pxp_tt, posfilter : path
        The ``pxp_tt`` and ``POS_FREED_TRANS_TWTT`` files.
    site : Site or path
        The site, or its file (:func:`~sblsim.orchestrator.surveys.gnatss_site.read_site`).

    Returns
    -------
    log : pandas.DataFrame
        The columns :data:`LOG_COLUMNS`, sorted by ping and the transponders' order; ``ping`` counts the
        pings in time order from 0 (a ping with no reply keeps its number; it has no row).
    site : Site

    Raises
    ------
    ModelError
        Any flaw of a file (see :func:`~sblsim.orchestrator.surveys.gnatss_files.read_pxp_tt`,
        :func:`~sblsim.orchestrator.surveys.gnatss_files.read_posfilter`,
        :func:`~sblsim.orchestrator.surveys.gnatss_site.read_site`); two pings at
        one time; two different positions at one time; a position farther than 100 km from the site's origin on
        an axis (:data:`~sblsim.orchestrator.surveys.log.POSITION_RANGE`); no position at a transmit or a
        reply's time (naming the pxp_tt line); a travel time not longer than its transponder's turnaround; no
        reply at all.
    """
    site = site if isinstance(site, Site) else read_site(site)
    pings = read_pxp_tt(pxp_tt, len(site.transponders)).sort_values("t_tx_s", kind="stable")
    repeated = pings["t_tx_s"].duplicated(keep=False)
    if repeated.any():
        lines = pings.loc[repeated, "line"].tolist()[:2]
        raise ModelError(f"pxp_tt: {str(pxp_tt)!r} lines {lines[0]} and {lines[1]} are two pings at one time")
    positions = read_posfilter(posfilter)
    # the epoch of a line in whole microseconds: pxp_tt's resolution (reply = transmit + TWTT [us])
    keys = np.round(positions["t_j2000_s"].to_numpy() * 1e6).astype(np.int64)
    values = positions[["x_m", "y_m", "z_m", *[f"c{k}" for k in range(9)]]].to_numpy()
    order = np.argsort(keys, kind="stable")
    keys, values, lines = keys[order], values[order], positions["line"].to_numpy()[order]
    same = np.flatnonzero(keys[1:] == keys[:-1])
    clash = same[np.any(values[same] != values[same + 1], axis=1)]
    if clash.size:
        k = clash[0]
        raise ModelError(f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} lines {lines[k]} and {lines[k + 1]} give two "
                         "different positions at one time")
    rotation = enu_rotation(site.lat_deg, site.lon_deg)
    enu = ecef_to_enu(values[:, :3], site.lat_deg, site.lon_deg, site.height_m)
    far = np.flatnonzero(np.any(np.abs(enu) > POSITION_RANGE[1], axis=1))
    if far.size:
        _near_origin(enu[far[0]], f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} line {lines[far[0]]}")
    cov = values[:, 3:].reshape(-1, 3, 3)
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    sigma = np.sqrt(np.einsum("ij,njk,ik->ni", rotation, cov, rotation))

    def lookup(key: int, line: int, what: str) -> int:
        k = int(np.searchsorted(keys, key))
        if k >= keys.size or keys[k] != key:
            raise ModelError(f"POS_FREED_TRANS_TWTT: {str(posfilter)!r} has no position at {key / 1e6:.6f} s "
                             f"since J2000, the {what} of pxp_tt line {line} (a truncated or another day's file?)")
        return k

    rows = []
    for ping, record in enumerate(pings.itertuples(index=False)):
        t_tx = float(record.t_tx_s)
        tx_key = int(round((t_tx - J2000_POSIX) * 1e6))
        tx = lookup(tx_key, record.line, "transmission")
        for transponder in site.transponders:
            us = float(getattr(record, f"twtt_us_{transponder.column}"))
            if us == 0.0:
                continue
            twtt = us * 1e-6 - transponder.turnaround_s
            if twtt <= 0.0:
                raise ModelError(f"pxp_tt: {str(pxp_tt)!r} line {record.line}: column {2 + transponder.column} "
                                 f"(two-way travel time [us]): {us:.0f} is not longer than {transponder.id}'s "
                                 f"turnaround {transponder.turnaround_s:g} s")
            rx = lookup(tx_key + int(round(us)), record.line, f"reply of {transponder.id}")
            rows.append((ping, transponder.id, t_tx, *enu[tx], *sigma[tx], t_tx + us * 1e-6, *enu[rx], *sigma[rx],
                         twtt))
    if not rows:
        raise ModelError(f"pxp_tt: {str(pxp_tt)!r} holds no reply (every two-way travel time is 0); at least one is "
                         "needed")
    log = pd.DataFrame(rows, columns=list(LOG_COLUMNS))
    return log.astype({"ping": np.int64, "transponder": str}), site


def community_editing(log: pd.DataFrame, site: Site) -> pd.DataFrame:
    """The pings the community keeps at a site: every transponder replied, the 3-D GNSS sigma of the transmit
    and of every receive position at most ``site.gnss_sigma_limit_m`` (``sqrt(σe² + σn² + σu²)``, the
    square root of the covariance's trace), the transmit point within ``site.distance_limit_m`` of the
    origin horizontally.

    Parameters
    ----------
    log : pandas.DataFrame
        A calibration log (:data:`LOG_COLUMNS`).
    site : Site

    Returns
    -------
    pandas.DataFrame
        The rows of the pings kept, in the log's order (index reset).
    """
    tx3 = np.sqrt(log["tx_sigma_e_m"] ** 2 + log["tx_sigma_n_m"] ** 2 + log["tx_sigma_u_m"] ** 2)
    rx3 = np.sqrt(log["rx_sigma_e_m"] ** 2 + log["rx_sigma_n_m"] ** 2 + log["rx_sigma_u_m"] ** 2)
    good = (tx3 <= site.gnss_sigma_limit_m) & (rx3 <= site.gnss_sigma_limit_m) & \
        (np.hypot(log["tx_e_m"], log["tx_n_m"]) <= site.distance_limit_m)
    ids = {t.id for t in site.transponders}
    per_ping = log.assign(good=good).groupby("ping").agg(good=("good", "all"), ids=("transponder", set))
    kept = per_ping.index[per_ping["good"] & per_ping["ids"].map(lambda s: s == ids)]
    return log[log["ping"].isin(kept)].reset_index(drop=True)


def _modelled(log: pd.DataFrame, site: Site, shift: np.ndarray) -> np.ndarray:
    """The straight-ray two-way travel time of each row with the array shifted by ``shift`` [s]."""
    by_id = {t.id: t for t in site.transponders}
    x = np.array([[by_id[i].e_m, by_id[i].n_m, by_id[i].u_m] for i in log["transponder"]]) + shift
    c = np.array([by_id[i].sound_speed_mps for i in log["transponder"]])
    a = x - log[["tx_e_m", "tx_n_m", "tx_u_m"]].to_numpy()
    b = x - log[["rx_e_m", "rx_n_m", "rx_u_m"]].to_numpy()
    ra, rb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    return (ra + rb) / c


def straight_ray_residuals(log: pd.DataFrame, site: Site, shift: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Observed minus modelled two-way travel time of each row [s]: the model is the straight two-leg path
    ``|p_tx − x| + |x − p_rx|`` from the a-priori transponder position x (plus ``shift`` [m, ENU]) at the
    transponder's harmonic-mean sound speed.

    Returns
    -------
    ndarray, shape (rows,)
    """
    modelled = _modelled(log, site, np.asarray(shift, dtype=float))
    return log["twtt_s"].to_numpy() - modelled


def ncl1_paths() -> tuple[Path, Path, Path]:
    """The vendored NCL1 day-208 files: ``pxp_tt``, ``POS_FREED_TRANS_TWTT``, ``site.toml``."""
    folder = resources.files(DATA[0]).joinpath(DATA[1])
    return tuple(Path(str(folder.joinpath(name))) for name in ("pxp_tt", "POS_FREED_TRANS_TWTT", "site.toml"))


def read_ncl1() -> tuple[pd.DataFrame, Site]:
    """The built-in survey B, GNATSS's NCL1 day 208 (2022-07-27): its log (all replies) and its site."""
    return read_gnatss(*ncl1_paths())


def main(argv: Sequence[str] | None = None) -> int:
    """Write a GNATSS survey as a calibration log (CSV): ``python -m sblsim.orchestrator.surveys.gnatss``.

    Returns
    -------
    int
        0, or 2 with one line on standard error for bad input (nothing written).
    """
    parser = argparse.ArgumentParser(prog="python -m sblsim.orchestrator.surveys.gnatss",
                                     description="Read a GNATSS survey (default: NCL1 day 208) into the "
                                                 "calibration log format.")
    pxp, pos, site = ncl1_paths()
    parser.add_argument("--pxp-tt", default=pxp, type=Path, help="the pxp_tt file")
    parser.add_argument("--posfilter", default=pos, type=Path, help="the POS_FREED_TRANS_TWTT file")
    parser.add_argument("--site", default=site, type=Path, help="the site file (TOML)")
    parser.add_argument("--edit", action="store_true", help="keep only the pings of the community editing")
    parser.add_argument("--out", required=True, type=Path, help="the log to write (.csv; must not exist)")
    args = parser.parse_args(argv)
    try:
        if args.out.suffix.lower() != ".csv":
            raise ModelError(f"--out: {str(args.out)!r} must be a .csv file")
        if args.out.exists() or args.out.is_symlink():
            raise ModelError(f"--out: {str(args.out)!r} exists; choose another file")
        log, site_ = read_gnatss(args.pxp_tt, args.posfilter, args.site)
        if args.edit:
            log = community_editing(log, site_)
        write_atomic(args.out, lambda tmp: log.to_csv(tmp, index=False))
    except ModelError as exc:
        print(f"sblsim: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"sblsim: error: --out: {str(args.out)!r} cannot be written ({exc.strerror})", file=sys.stderr)
        return 2
    print(f"{len(log)} replies of {log['ping'].nunique()} pings written to {args.out}")
    return 0


__all__ = ["community_editing", "ncl1_paths", "read_gnatss", "read_ncl1", "straight_ray_residuals"]

if __name__ == "__main__":
    sys.exit(main())
