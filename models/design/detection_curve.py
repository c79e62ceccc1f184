"""The detection range curve of a telemetry range test: the probability that a receiver hears one ping against the
distance between the tag and the receiver.

Range tests moor tags at known distances from receivers and count the pings heard; the share heard against the
distance is fitted by a logistic regression, ``logit P(d) = β₀ + β₁ d`` (Kessel, Cooke, Heupel, Hussey,
Simpfendorfer, Vagle, Fisk, "A review of detection range testing in aquatic passive acoustic telemetry studies",
Reviews in Fish Biology and Fisheries 24:199–218, 2014, doi:10.1007/s11160-013-9328-4), or reported as a table of
distances and shares. Two forms here:

* **logistic**: ``P(d) = 1 / (1 + exp(slope · (d − range_50_m)))``, ``range_50_m`` the distance heard half the
  time [m] (``−β₀ / β₁``) and ``slope`` how fast the probability falls there [1/m] (``−β₁``): P falls from 0.9 to
  0.1 over ``2 ln 9 / slope`` ≈ ``4.39 / slope`` metres;
* **table**: distances [m] (increasing, from 0 or more) and probabilities [0–1] (non-increasing: a range test's
  curve, monotone), linearly interpolated between rows and held at the first and last rows' values outside them;
* **the site's SNR model** (:meth:`DetectionCurve.sonar_equation`), where no range test is at hand: the passive
  sonar equation of the tag's source level (its power class) at the site, ``P(d) = Φ((SL − TL(d) − NL + DI − DT) /
  σ_f)`` with ``TL(d) = 20 log10 d + α d`` (spherical spreading and absorption; Urick, *Principles of Underwater
  Sound*, 3rd ed., McGraw-Hill 1983, ch. 2 and §12.1–12.3), α of Francois & Garrison (1982) and NL of the Wenz
  curves (:mod:`sblsim.models.acoustics.volume_absorption`, :mod:`~sblsim.models.acoustics.ambient_noise`,
  :mod:`~sblsim.models.acoustics.sonar`), tabulated once on :data:`SNR_TABLE_ROWS` distances and then a
  table as above. Range testing's practice (Kessel et al. 2014 above) is to measure the curve at the site, the
  sonar equation being the prediction a study makes before it. Coded fish tags' source levels as measured:
  Bowles, Denes, Shane, "Acoustic characteristics of ultrasonic coded transmitters for fishery applications:
  could marine mammals hear them?", J. Acoust. Soc. Am. 128(5):3223–3231, 2010.

The keys a design names them by are ``detection.range_50_m``, ``detection.slope`` and ``detection.table``
(:meth:`DetectionCurve.from_mapping`); a curve per receiver (``detection.per_receiver``: the receivers in place,
each with its own range test's logistic curve) is a :class:`ReceiverCurves`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.acoustics import ambient_noise, sonar, volume_absorption
from sblsim.models.errors import ModelError

#: The allowed ``detection.range_50_m`` [m]: (0, this].
RANGE_50_MAX_M = 100_000.0
#: The allowed ``detection.slope`` [1/m]: (0, this].
SLOPE_MAX = 10.0
#: The most rows of ``detection.table``.
TABLE_MAX_ROWS = 10_000
#: The rows of the site's SNR model's table (:meth:`DetectionCurve.sonar_equation`), evenly spaced from 0 m to where
#: the mean SNR is :data:`SNR_TAIL` fluctuations (at least 1 dB) below the detection threshold.
SNR_TABLE_ROWS, SNR_TAIL = 4000, 6.0


@dataclass(frozen=True)
class DetectionCurve:
    """A detection range curve (module docstring): logistic (``range_50_m``, ``slope``) or a table.

    Build it with :meth:`logistic`, :meth:`table` or :meth:`from_mapping`, which check the values.

    Attributes
    ----------
    range_50_m : float or None
        The logistic curve's 50 % range [m]; None for a table.
    slope : float or None
        The logistic curve's slope at it [1/m]; None for a table.
    distances_m : tuple of float
        The table's distances [m] (empty for a logistic curve).
    probabilities : tuple of float
        The table's probabilities [0–1] (empty for a logistic curve).
    """

    range_50_m: float | None = None
    slope: float | None = None
    distances_m: tuple[float, ...] = ()
    probabilities: tuple[float, ...] = ()
    model: str = ""

    @classmethod
    def sonar_equation(cls, source_level_db: float, frequency_hz: float, bandwidth_hz: float, beaufort: int,
                       shipping: float, threshold_db: float, fluctuation_db: float, directivity_db: float = 0.0,
                       temperature_c: float = 10.0, salinity: float = 35.0,
                       rows: int = SNR_TABLE_ROWS) -> DetectionCurve:
        """The site's SNR model (module docstring) as a table of ``rows`` distances.

        ``P(d) = detection_probability(snr(SL, TL(d), NL, DI), DT, σ_f)`` with ``TL(d) = 20 log10 max(d, 1 m) +
        α max(d, 1 m)`` (the source level holds at 1 m), ``α = absorption(f, T, S, 0 m)``, ``NL =
        noise_level(f, B, wind_speed(beaufort), shipping)`` (:mod:`sblsim.models.acoustics.sonar`,
        :mod:`~sblsim.models.acoustics.volume_absorption`, :mod:`~sblsim.models.acoustics.ambient_noise`); the table
        from 0 m to the distance where the mean SNR is :data:`SNR_TAIL` σ_f (at least 1 dB) below DT
        (:func:`~sblsim.models.acoustics.sonar.detection_range`), held at its last value (about 0) beyond.

        Parameters
        ----------
        source_level_db : float
            SL, the tag's source level [dB re 1 µPa at 1 m].
        frequency_hz, bandwidth_hz : float
            The tag's frequency and the receiver's noise band [Hz].
        beaufort : int
            The sea state of the wind noise (0–8).
        shipping : float
            The shipping activity, 0 to 1.
        threshold_db : float
            DT, the SNR heard half the time [dB].
        fluctuation_db : float
            σ_f, the received level's log-normal fluctuation [dB] (0: a step).
        directivity_db : float, optional
            DI, the receiver's directivity index [dB].
        temperature_c, salinity : float, optional
            The water's temperature [°C] and salinity [g/kg] (the absorption; 0 g/kg: fresh water, the pure
            water's term alone).
        rows : int, optional
            The table's rows.

        Returns
        -------
        DetectionCurve
            A table whose ``model`` says the SNR model's numbers.

        Raises
        ------
        ModelError
            Naming ``tag.source_level_db``: a tag heard nowhere (the mean SNR at 1 m below the table's floor), or
            one heard beyond 1,000 km.
        """
        wind = ambient_noise.wind_speed(beaufort)
        alpha = float(volume_absorption.absorption(frequency_hz, temperature_c, salinity, 0.0))
        noise = float(ambient_noise.noise_level(frequency_hz, bandwidth_hz, wind, shipping))
        floor = threshold_db - max(SNR_TAIL * fluctuation_db, 1.0)
        try:
            far = sonar.detection_range(frequency_hz, bandwidth_hz, source_level_db, directivity_db, floor, wind,
                                        shipping, temperature_c, salinity, 0.0)
        except ModelError:
            excess = source_level_db - noise + directivity_db - threshold_db
            raise ModelError(f"tag.source_level_db: {source_level_db:g} dB gives an SNR {excess:.1f} dB from the "
                             f"detection threshold at 1 m (noise {noise:.1f} dB re 1 uPa in the band): heard nowhere "
                             "or beyond 1000 km; allowed a source level the site hears within them") from None
        d = np.linspace(0.0, far, rows)
        r = np.maximum(d, 1.0)
        mean_snr = sonar.snr(source_level_db, 20.0 * np.log10(r) + alpha * r, noise, directivity_db)
        p = np.asarray(sonar.detection_probability(ca.DM(mean_snr), threshold_db, fluctuation_db), dtype=float)
        p = np.minimum.accumulate(np.clip(p.ravel(), 0.0, 1.0))  # monotone to round-off
        curve = cls(distances_m=tuple(d.tolist()), probabilities=tuple(p.tolist()))
        model = (f"SNR model: SL {source_level_db:g} dB, {frequency_hz / 1000:g} kHz, NL {noise:.1f} dB in "
                 f"{bandwidth_hz:g} Hz, absorption {1000 * alpha:.3g} dB/km, DT {threshold_db:g} dB, fluctuation "
                 f"{fluctuation_db:g} dB: 50 % at {curve.range_at(0.5):.0f} m, 10 % at {curve.range_at(0.1):.0f} m")
        return cls(distances_m=curve.distances_m, probabilities=curve.probabilities, model=model)

    @classmethod
    def logistic(cls, range_50_m: float, slope: float, key: str = "detection") -> DetectionCurve:
        """The logistic curve ``1 / (1 + exp(slope · (d − range_50_m)))``.

        Parameters
        ----------
        range_50_m : float
            The distance heard half the time [m], in (0, :data:`RANGE_50_MAX_M`].
        slope : float
            [1/m], in (0, :data:`SLOPE_MAX`].
        key : str, optional
            The table the keys are named under in the errors.

        Raises
        ------
        ModelError
            Naming ``<key>.range_50_m`` or ``<key>.slope`` and the allowed range.
        """
        r50 = _number(range_50_m, f"{key}.range_50_m", f"(0, {RANGE_50_MAX_M:g}] m")
        if not 0.0 < r50 <= RANGE_50_MAX_M:
            raise ModelError(f"{key}.range_50_m: {r50:g} m is outside the allowed range (0, {RANGE_50_MAX_M:g}] m")
        k = _number(slope, f"{key}.slope", f"(0, {SLOPE_MAX:g}] 1/m")
        if not 0.0 < k <= SLOPE_MAX:
            raise ModelError(f"{key}.slope: {k:g} 1/m is outside the allowed range (0, {SLOPE_MAX:g}] 1/m (a "
                             "probability that falls with the distance)")
        return cls(range_50_m=r50, slope=k)

    @classmethod
    def table(cls, distances_m, probabilities, key: str = "detection") -> DetectionCurve:
        """A table of distances [m] and the probabilities heard there [0–1], interpolated linearly.

        Parameters
        ----------
        distances_m : array_like, shape (K,)
            At least 2, strictly increasing, finite, from 0 m or more.
        probabilities : array_like, shape (K,)
            In [0, 1], non-increasing with the distance.
        key : str, optional
            The table the keys are named under in the errors.

        Raises
        ------
        ModelError
            Naming ``<key>.table`` and what is allowed.
        """
        name = f"{key}.table"
        try:
            d = np.asarray(distances_m, dtype=float).ravel()
            p = np.asarray(probabilities, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ModelError(f"{name}: expected rows of numbers [distance_m, probability]") from None
        if d.shape != p.shape or not 2 <= len(d) <= TABLE_MAX_ROWS:
            raise ModelError(f"{name}: {len(d)} distances and {len(p)} probabilities; allowed 2 to "
                             f"{TABLE_MAX_ROWS} rows [distance_m, probability]")
        if not (np.isfinite(d).all() and np.isfinite(p).all()):
            raise ModelError(f"{name}: a value is not finite; allowed distances [0, inf) m and probabilities [0, 1]")
        if d[0] < 0.0 or np.any(np.diff(d) <= 0.0):
            raise ModelError(f"{name}: distances {_shown(d)} m; allowed from 0 m up, strictly increasing")
        if np.any((p < 0.0) | (p > 1.0)):
            raise ModelError(f"{name}: probabilities {_shown(p)}; allowed in [0, 1]")
        if np.any(np.diff(p) > 0.0):
            raise ModelError(f"{name}: probabilities {_shown(p)} rise with the distance; allowed non-increasing "
                             "(a range test's curve)")
        return cls(distances_m=tuple(d.tolist()), probabilities=tuple(p.tolist()))

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], key: str = "detection") -> DetectionCurve:
        """The curve of a ``[detection]`` table: ``range_50_m`` and ``slope``, or ``table`` (rows
        ``[distance_m, probability]``), not both.

        Raises
        ------
        ModelError
            Naming the key at fault (``detection.range_50_m``, ``detection.slope``, ``detection.table``, or an
            unknown key) and what is allowed.
        """
        known = {"range_50_m", "slope", "table"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ModelError(f"{key}.{unknown[0]}: unknown key; allowed range_50_m and slope, or table")
        if "table" in values:
            extra = sorted(known & set(values) - {"table"})
            if extra:
                raise ModelError(f"{key}.{extra[0]}: given with {key}.table; allowed range_50_m and slope, or table")
            rows = values["table"]
            try:
                rows = np.asarray(rows, dtype=float)
            except (TypeError, ValueError):
                raise ModelError(f"{key}.table: expected rows of numbers [distance_m, probability]") from None
            if rows.ndim != 2 or rows.shape[1] != 2:
                raise ModelError(f"{key}.table: shape {rows.shape}; allowed rows [distance_m, probability]")
            return cls.table(rows[:, 0], rows[:, 1], key)
        for name in ("range_50_m", "slope"):
            if name not in values:
                raise ModelError(f"{key}.{name}: missing; allowed range_50_m and slope, or table")
        return cls.logistic(values["range_50_m"], values["slope"], key)

    @property
    def kind(self) -> str:
        """``logistic`` or ``table``."""
        return "table" if self.distances_m else "logistic"

    def probability(self, distance_m) -> np.ndarray:
        """The probability that one ping is heard at each distance.

        Parameters
        ----------
        distance_m : array_like, any shape
            [m], 0 or more.

        Returns
        -------
        ndarray, the same shape
            [0–1].
        """
        d = np.asarray(distance_m, dtype=float)
        if self.kind == "table":
            return np.interp(d, self.distances_m, self.probabilities)
        # 1 / (1 + e^x) as the logistic's stable form: e^-x / (1 + e^-x) for x > 0
        x = self.slope * (d - self.range_50_m)
        e = np.exp(-np.abs(x))
        return np.where(x > 0.0, e / (1.0 + e), 1.0 / (1.0 + e))

    def range_at(self, probability: float) -> float:
        """The distance [m] heard with ``probability`` (in (0, 1)) on a logistic curve:
        ``range_50_m + ln((1 − P) / P) / slope``; for a table, the smallest distance whose interpolated
        probability is ``probability`` or less (``inf`` if none).

        Raises
        ------
        ModelError
            For a probability outside (0, 1).
        """
        if not 0.0 < probability < 1.0:
            raise ModelError(f"detection probability {probability!r}: allowed (0, 1)")
        if self.kind == "logistic":
            return self.range_50_m + math.log((1.0 - probability) / probability) / self.slope
        d, p = np.asarray(self.distances_m), np.asarray(self.probabilities)
        below = np.flatnonzero(p <= probability)
        if not len(below):
            return math.inf
        j = below[0]
        if j == 0:
            return float(d[0])
        # linear between rows j − 1 (above) and j (at or below)
        return float(d[j - 1] + (p[j - 1] - probability) / (p[j - 1] - p[j]) * (d[j] - d[j - 1]))

    def describe(self) -> str:
        """One line: the curve's form and numbers."""
        if self.model:
            return self.model
        if self.kind == "logistic":
            return (f"logistic: 50 % at {self.range_50_m:g} m, slope {self.slope:g} 1/m (90 % at "
                    f"{self.range_at(0.9):.0f} m, 10 % at {self.range_at(0.1):.0f} m)")
        return f"table of {len(self.distances_m)} rows, {self.distances_m[0]:g}–{self.distances_m[-1]:g} m"


@dataclass(frozen=True)
class ReceiverCurves:
    """Detection range curves receiver by receiver: a layout's ``k``-th receiver hears with ``curves[k]`` (its own
    range test's), or with ``site`` where that is None or beyond ``curves`` (the receivers with a curve of their own
    come first in every layout: those already in place).

    Attributes
    ----------
    site : DetectionCurve
        The site-wide curve.
    curves : tuple of DetectionCurve or None
        The first receivers' own curves.
    """

    site: DetectionCurve
    curves: tuple[DetectionCurve | None, ...] = ()

    def probability(self, distance_m) -> np.ndarray:
        """The probability that one ping is heard by each receiver at each distance.

        Parameters
        ----------
        distance_m : array_like, shape (..., n)
            [m], 0 or more; the last axis a layout's receivers, in its order.

        Returns
        -------
        ndarray, shape (..., n)
            [0–1]: column ``k`` by ``curves[k]``, the others by ``site``.
        """
        d = np.asarray(distance_m, dtype=float)
        p = np.array(self.site.probability(d), dtype=float)
        if d.ndim:
            for k, curve in enumerate(self.curves[:d.shape[-1]]):
                if curve is not None:
                    p[..., k] = curve.probability(d[..., k])
        return p

    def describe(self) -> str:
        """One line: the site's curve and how many receivers have their own."""
        own = sum(c is not None for c in self.curves)
        return f"{self.site.describe()}; {own} receiver(s) with a curve of their own"


def _number(value, name: str, allowed: str) -> float:
    """``value`` as a finite float, or a :class:`ModelError` naming ``name`` and ``allowed``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ModelError(f"{name}: expected a number, got {value!r}; allowed {allowed}")
    if not math.isfinite(float(value)):
        raise ModelError(f"{name}: {value!r} is not finite; allowed {allowed}")
    return float(value)


def _shown(values: np.ndarray, most: int = 6) -> str:
    """A few values for an error message."""
    text = ", ".join(f"{v:g}" for v in values[:most])
    return f"[{text}{', …' if len(values) > most else ''}]"


__all__ = ["RANGE_50_MAX_M", "SLOPE_MAX", "SNR_TABLE_ROWS", "SNR_TAIL", "TABLE_MAX_ROWS", "DetectionCurve",
           "ReceiverCurves"]
