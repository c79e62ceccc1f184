"""The receivers' survey error a synchronisation's residuals show (:mod:`sblsim.models.sync.survey_error`), from its
tables: each pair of a sync tag and a receiver that heard it, not its own, with at least
:data:`~sblsim.models.sync.survey_error.MIN_PAIR_ARRIVALS` arrivals with a residual (the fit's rejected ones too);
their median residual, robust scale and count; the receivers' positions as the table gives them.

Units: metres [m].
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.models.sync.survey_error import MIN_PAIR_ARRIVALS, SurveyError, survey_error


def pairs(residuals: pd.DataFrame, rejected: bool = False) -> pd.DataFrame:
    """Each (``receiver``, ``tag``) pair of a synchronisation's kept arrivals at a distance [m] (a sync tag heard at a
    receiver not its own), with at least :data:`MIN_PAIR_ARRIVALS` of them: their ``median`` residual [m], robust
    ``scale`` [m] (1.4826 × the median absolute deviation) and ``count``. With ``rejected`` the arrivals the fit
    rejected are in too (every arrival with a residual): a position off by more than the timing noise allows makes
    the arrivals of its pairs look like outliers, and leaving them out hides the error sought (the median keeps a
    late arrival from counting)."""
    used = residuals["kept"].to_numpy(bool) if not rejected else np.isfinite(residuals["residual_m"].to_numpy(float))
    used = used & (residuals["distance_m"].to_numpy(float) > 0)
    # grouped by one integer key of the two columns' codes, not by their texts (a season's arrivals: a groupby on two
    # text keys makes its own lookups of every row's texts)
    receiver, receivers = pd.factorize(residuals["receiver"].astype(str))
    tag, tags = pd.factorize(residuals["tag"].astype(str))
    return _grouped(receiver, receivers, tag, tags, residuals["residual_m"].to_numpy(float), used)


def _grouped(receiver: np.ndarray, receivers: pd.Index, tag: np.ndarray, tags: pd.Index, residual_m: np.ndarray,
             used: np.ndarray) -> pd.DataFrame:
    """:func:`pairs` of the arrivals ``used`` (n,), each of receiver ``receivers[receiver]`` and sync tag
    ``tags[tag]`` (integer codes (n,)) with its residual [m]. A pair's median and median absolute deviation are
    NumPy's (``numpy.median``) over its slice of the arrivals sorted once by pair, its residuals without a value
    (NaN) left out of both and counted (as pandas' group median and size: the same figures to the bit, a season's
    arrivals without its group-by's copies of every row)."""
    n = max(len(tags), 1)
    key = receiver[used].astype(np.int64, copy=False)  # (a copy: the selection's own)
    key *= n
    key += tag[used]
    values = residual_m[used]
    order = np.argsort(key, kind="stable")
    key = key[order]
    values = values[order]
    del order
    first = np.flatnonzero(np.diff(key, prepend=-1))  # each pair's first arrival (the keys are 0 or more)
    count = np.diff(np.append(first, len(key)))
    median, scale = np.full(len(first), np.nan), np.full(len(first), np.nan)
    for g, (start, size) in enumerate(zip(first, count)):
        mine = values[start:start + size]
        mine = mine[~np.isnan(mine)]
        if len(mine):
            median[g] = np.median(mine)
            scale[g] = 1.4826 * np.median(np.abs(mine - median[g]))
    pair = key[first]
    table = pd.DataFrame({"receiver": receivers.take(pair // n), "tag": tags.take(pair % n), "median": median,
                          "count": count.astype(np.int64), "scale": scale})
    table = table[table["count"] >= MIN_PAIR_ARRIVALS]
    return table.sort_values(["receiver", "tag"]).reset_index(drop=True)  # (as a groupby on the texts orders them)


def seen_survey_error(residuals: pd.DataFrame, sync_tags: pd.DataFrame, receivers: pd.DataFrame
                      ) -> SurveyError | None:
    """The survey error the residuals show (:func:`~sblsim.models.sync.survey_error.survey_error`); None where no
    pair is left.

    Parameters
    ----------
    residuals : pandas.DataFrame
        ``residuals.csv``: ``receiver``, ``tag``, ``distance_m``, ``residual_m``, ``kept``.
    sync_tags : pandas.DataFrame
        ``sync_tags.csv``: each sync tag's own ``receiver`` (a tag without a row there left out).
    receivers : pandas.DataFrame
        The receivers' ``receiver``, ``x``, ``y`` [m] as the table gives them.
    """
    home = dict(zip(sync_tags["tag"].astype(str), sync_tags["receiver"].astype(str)))
    return _seen(pairs(residuals, rejected=True), home, receivers["receiver"].astype(str).tolist(),
                 receivers[["x", "y"]].to_numpy(float))


def seen_in_fit(receiver: np.ndarray, tag: np.ndarray, residual_m: np.ndarray, distance: np.ndarray,
                names: list[str], tag_names: list[str], tag_home: np.ndarray, positions: np.ndarray
                ) -> SurveyError | None:
    """:func:`seen_survey_error` from a synchronisation's own arrays, before its tables are made (so that the sync
    tags' scores may take it): the pairs of every sync tag of ``tag_names``, those ``sync_tags.csv`` has no row
    for (too few arrivals to be positioned without their own receiver) too.

    Parameters
    ----------
    receiver, tag : ndarray of int, (n,)
        Each arrival's receiver (a row of ``names``) and sync tag (of ``tag_names``).
    residual_m : ndarray, (n,)
        Its residual [m] (NaN where it has none).
    distance : ndarray, (n,)
        From the tag's own receiver [m] (0: its own).
    names, tag_names : list of str
    tag_home : ndarray of int, (tags,)
        Each sync tag's own receiver.
    positions : ndarray, (R, ≥ 2)
        The receivers' positions as the table gives them [m].
    """
    used = np.isfinite(residual_m) & (distance > 0)
    table = _grouped(receiver, pd.Index(names), tag, pd.Index(tag_names), residual_m, used)
    return _seen(table, {t: names[h] for t, h in zip(tag_names, tag_home)}, names, positions)


def _seen(table: pd.DataFrame, home: dict[str, str], names: list[str], positions: np.ndarray) -> SurveyError | None:
    """The survey error of the pairs ``table`` (:func:`pairs`), each tag's own receiver by ``home``, the receivers
    ``names`` at ``positions`` [m]; None where no pair is left."""
    index = {n: i for i, n in enumerate(names)}
    own = table["tag"].map(home)
    table, own = (t[own.isin(index) & table["receiver"].isin(index) & (own != table["receiver"])] for t in (table, own))
    if not len(table):
        return None
    tags = {t: i for i, t in enumerate(sorted(set(table["tag"])))}
    return survey_error(table["median"].to_numpy(float), table["count"].to_numpy(float),
                        table["scale"].to_numpy(float), table["receiver"].map(index).to_numpy(int),
                        own.map(index).to_numpy(int), table["tag"].map(tags).to_numpy(int),
                        np.asarray(positions, float)[:, :2])


__all__ = ["pairs", "seen_in_fit", "seen_survey_error"]
