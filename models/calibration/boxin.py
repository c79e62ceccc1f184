"""A simulated calibration survey (box-in): a vessel sails a pattern around a seafloor transponder and
interrogates it.

The vessel's GNSS antenna follows a closed pattern at the surface (a ``circle`` of radius :math:`R`, a ``box``
of half-side :math:`R` or a ``figure-eight`` of half-width :math:`R`, centred over the a-priori transponder
position) at a constant speed, heading along the track; its transducer hangs at the lever arm
:math:`\\mathbf a = (0, 0, h)` (body frame, :math:`h` = ``platform.transducer_depth`` below the antenna), so
the transducer is at :math:`\\mathbf p(t) = \\mathbf g(t) + R(\\phi, \\theta, \\psi)\\,\\mathbf a` (roll and pitch
zero, yaw the course). Every ``ping_period_s`` the transducer transmits at :math:`t_\\mathrm{tx}`; the ping
reaches the transponder :math:`\\mathbf x` after :math:`|\\mathbf p(t_\\mathrm{tx}) - \\mathbf x| / c`, which replies
after its turnaround :math:`\\tau` plus a jitter :math:`\\delta\\tau \\sim N(0, \\sigma_\\tau^2)`, and the reply
reaches the moving transducer at the :math:`t_\\mathrm{rx}` solving
:math:`t_\\mathrm{rx} = t_\\mathrm{reply} + |\\mathbf p(t_\\mathrm{rx}) - \\mathbf x| / c` (a fixed point, iterated to
machine precision). The recorded TWTT, turnaround removed, is

.. math:: T = (|\\mathbf p_\\mathrm{tx} - \\mathbf x| + |\\mathbf x - \\mathbf p_\\mathrm{rx}|)/c + \\delta\\tau + n_T,
          \\quad n_T \\sim N(0, \\sigma_T^2),

a straight ray at the sound speed :math:`c` (the water column's harmonic mean). The recorded transducer
positions are the GNSS position plus the lever arm turned by the *measured* attitude,
:math:`\\tilde{\\mathbf p} = \\mathbf g + \\mathbf e_\\mathrm{GNSS} + R(\\phi + \\epsilon_\\phi, \\theta +
\\epsilon_\\theta, \\psi + \\epsilon_\\psi)\\,\\mathbf a`, with the platform's error model
(:mod:`sblsim.models.platform.core`, the same parameters, units and defaults): the GNSS error per axis white
(``gps_sigma``) or first-order Gauss-Markov (``gps_tau``, its exact discretization between the survey's instants,
stationary start), the attitude error per axis ``imu_bias_deg`` plus white noise of ``imu_sigma_deg``. The rotation
is the platform's own (:func:`sblsim.models.platform.geometry.rotation_ned`, NED; turned here into the survey's
local ENU frame).

This is a numpy draw of the platform's error model at the survey's transmit and receive instants, not a run of
the platform component: the platform is moored at the origin (it does not sail a pattern), and a survey's
error sources are only its GNSS and attitude errors at those instants; the GNSS sample-and-hold of
``sample_period`` is left out (a transmission and its reply are more than a sample period apart).

The log's transducer sigmas are what a survey's GNSS/INS would report: per axis
:math:`\\sqrt{\\sigma_\\mathrm{GNSS}^2
+ \\sum_k (\\partial (R\\mathbf a)/\\partial \\vartheta_k\\,\\sigma_\\mathrm{IMU})^2}`
(the attitude noise through the lever arm, linearized; the bias is not in it), at least :data:`SIGMA_FLOOR`.

The true transponder is the a-priori position :math:`(0, 0, -d)` plus :math:`N(0, \\sigma_\\mathrm{apriori}^2 I)`
drawn once per replicate; each error source draws from its own stream (:func:`streams`), so that turning one
off leaves the others' numbers.

Sources: the box-in survey and its two-leg travel time as in S. Xie et al., "Shallow Water Seafloor Geodesy
with Wave Glider-Based GNSS-Acoustic Surveying of a Single Transponder", Earth and Space Science, 2023; the
platform's GNSS and IMU errors as in Cario et al., "Accurate Localization in Acoustic Underwater Localization
Systems", Sensors 21(3):762, 2021, Sections 3-4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.calibration.legs import SOUND_SPEED_RANGE
from sblsim.models.calibration.replies import Replies
from sblsim.models.declarations import Variable, parameters
from sblsim.models.platform.core import GPS_MODELS, Platform
from sblsim.models.platform.geometry import rotation_ned

#: The patterns a vessel sails.
PATTERNS = ("circle", "box", "figure-eight")
#: The smallest transducer sigma written in a log [m] (a log's sigmas are > 0; a noise-free survey has this).
SIGMA_FLOOR = 1e-6
#: The survey's first transmission, POSIX [s] (2026-01-01T00:00:00Z).
EPOCH = 1_767_225_600.0
#: Points of the polyline a pattern is sailed along (per closed pattern).
PATTERN_POINTS = 4096
#: The platform's parameters a simulated survey uses (names, units, ranges and defaults are the platform's).
PLATFORM_KEYS = ("gps_sigma", "gps_model", "gps_tau", "imu_sigma_deg", "imu_bias_deg", "transducer_depth")

#: The survey's own keys (section ``survey``).
SURVEY_VARIABLES = (
    Variable("pattern", "parameter", "String", "circle", description="The vessel's pattern around the transponder",
             choices=PATTERNS, scope="config"),
    Variable("radius_m", "parameter", "Real", 300.0, "m", "The pattern's radius (a box's half-side, a "
             "figure-eight's half-width)", min=1.0, max=20000.0),
    Variable("speed_mps", "parameter", "Real", 2.0, "m/s", "The vessel's speed over ground", min=0.1, max=20.0),
    Variable("duration_s", "parameter", "Real", 1200.0, "s", "The survey's duration", min=10.0, max=86400.0),
    Variable("ping_period_s", "parameter", "Real", 4.0, "s", "Time between interrogations", min=0.1, max=600.0),
    Variable("depth_m", "parameter", "Real", 300.0, "m", "The transponder's a-priori depth below the surface",
             min=1.0, max=12000.0),
    Variable("apriori_sigma_m", "parameter", "Real", 5.0, "m", "Std per axis of the true transponder about its "
             "a-priori position (drawn per replicate)", min=0.0, max=100.0),
    Variable("turnaround_s", "parameter", "Real", 0.2, "s", "The transponder's turnaround", min=0.0, max=60.0),
    Variable("turnaround_jitter_s", "parameter", "Real", 1e-5, "s", "Std of the turnaround's jitter",
             min=0.0, max=0.1),
    Variable("twtt_sigma_s", "parameter", "Real", 2e-5, "s", "Std of the TWTT measurement noise", min=0.0,
             max=0.1),
    Variable("sound_speed_mps", "parameter", "Real", 1500.0, "m/s", "The true sound speed (harmonic mean of the "
             "water column)", min=SOUND_SPEED_RANGE[0], max=SOUND_SPEED_RANGE[1]),
    Variable("sound_speed_error_mps", "parameter", "Real", 0.0, "m/s", "The solver's assumed sound speed minus "
             "the true one", min=-100.0, max=100.0),
    Variable("seed", "parameter", "Integer", 1, description="Seed of the survey's random draws (replicate r draws "
             "from the streams of (seed, r))", min=0, max=2**63 - 1),
    Variable("ntd_sigma_s", "parameter", "Real", 0.0, "s", "Std of the moving ocean's nadir total delay (two-way), "
             "a random smooth function of time (0: a still ocean)", min=0.0, max=0.01),
    Variable("ntd_time_scale_s", "parameter", "Real", 3600.0, "s", "Time scale of the delay's changes (its "
             "covariance exp(-dt^2 / (2 T^2)))", min=10.0, max=1e6),
    Variable("ntd_gradient_e_s", "parameter", "Real", 0.0, "s", "The moving ocean's deep gradient, East (SeaGap's g_d: "
             "the delay grows by it times tan(nadir angle) toward East)", min=-0.01, max=0.01),
    Variable("ntd_gradient_n_s", "parameter", "Real", 0.0, "s", "The moving ocean's deep gradient, North",
             min=-0.01, max=0.01),
)
#: Random cosines of the moving ocean's delay (random Fourier features of its squared-exponential covariance).
OCEAN_TERMS = 64


def platform_variables() -> dict[str, Variable]:
    """The platform's declarations of :data:`PLATFORM_KEYS` (declared once, in the platform)."""
    declared = parameters(Platform.variables())
    return {name: declared[name] for name in PLATFORM_KEYS}


# stream purposes
_TRUTH, _GNSS, _ATTITUDE, _JITTER, _TWTT, _OCEAN = range(6)


def streams(seed: int, replicate: int) -> dict[int, np.random.Generator]:
    """The random streams of one replicate, one per error source (numpy's PCG64 of the seed sequence
    ``(seed, replicate, purpose)``)."""
    return {k: np.random.default_rng([int(seed), int(replicate), k]) for k in (_TRUTH, _GNSS, _ATTITUDE, _JITTER,
                                                                              _TWTT, _OCEAN)}


def ocean_delay(t: np.ndarray, sigma: float, time_scale: float, rng: np.random.Generator) -> np.ndarray:
    """A random smooth delay of the moving ocean at times ``t`` [s]: a stationary Gaussian process of standard
    deviation ``sigma`` and covariance :math:`\\sigma^2 e^{-\\Delta t^2/(2T^2)}`, drawn as
    :data:`OCEAN_TERMS` random cosines :math:`\\sigma\\sqrt{2/K}\\sum_k \\cos(\\omega_k t + \\phi_k)`,
    :math:`\\omega_k \\sim N(0, 1/T^2)`, :math:`\\phi_k \\sim U(0, 2\\pi)` (A. Rahimi, B. Recht, "Random features
    for large-scale kernel machines", NIPS 2007).

    Returns
    -------
    numpy.ndarray, shape (n,)
        [s].
    """
    omega = rng.standard_normal(OCEAN_TERMS) / time_scale
    phase = rng.uniform(0.0, 2.0 * math.pi, OCEAN_TERMS)
    t = np.asarray(t, dtype=float)
    return sigma * math.sqrt(2.0 / OCEAN_TERMS) * np.sum(np.cos(np.outer(t, omega) + phase), axis=1)


def _outline(pattern: str, radius: float) -> np.ndarray:
    """The closed pattern as a polyline, (PATTERN_POINTS + 1, 2) East, North [m], first point repeated."""
    phi = np.linspace(0.0, 2.0 * math.pi, PATTERN_POINTS + 1)
    if pattern == "circle":  # from North, clockwise
        return np.column_stack((radius * np.sin(phi), radius * np.cos(phi)))
    if pattern == "figure-eight":  # Gerono's lemniscate, lobes East and West, through the centre
        return np.column_stack((radius * np.sin(phi), radius * np.sin(phi) * np.cos(phi)))
    corners = radius * np.array([[0, 1], [1, 1], [1, -1], [-1, -1], [-1, 1], [0, 1]], dtype=float)
    edges = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    s = np.concatenate(([0.0], np.cumsum(edges)))
    where = phi / (2.0 * math.pi) * s[-1]
    return np.column_stack((np.interp(where, s, corners[:, 0]), np.interp(where, s, corners[:, 1])))


def track(pattern: str, radius: float, speed: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The antenna's position and course at times ``t`` along the pattern, sailed at constant speed.

    Parameters
    ----------
    pattern : str
        One of :data:`PATTERNS`.
    radius, speed : float
        The pattern's radius [m] and the speed over ground [m/s].
    t : numpy.ndarray, shape (n,)
        Times from the survey's start [s].

    Returns
    -------
    position : numpy.ndarray, shape (n, 3)
        Local ENU [m] (at the surface, Up 0).
    course : numpy.ndarray, shape (n,)
        Course over ground, clockwise from North [rad] (the heading).
    """
    line = _outline(pattern, radius)
    step = np.diff(line, axis=0)
    s = np.concatenate(([0.0], np.cumsum(np.hypot(step[:, 0], step[:, 1]))))
    where = np.mod(speed * np.asarray(t, dtype=float), s[-1])
    segment = np.clip(np.searchsorted(s, where, side="right") - 1, 0, len(step) - 1)
    position = np.column_stack((np.interp(where, s, line[:, 0]), np.interp(where, s, line[:, 1]),
                                np.zeros_like(where)))
    return position, np.arctan2(step[segment, 0], step[segment, 1])


@cache
def _lever():
    """casadi functions of (roll, pitch, yaw, arm): the arm turned to NED, and its Jacobian w.r.t. the angles."""
    angles, arm = ca.SX.sym("angles", 3), ca.SX.sym("arm", 3)
    turned = ca.mtimes(rotation_ned(angles[0], angles[1], angles[2]), arm)
    return (ca.Function("lever", [angles, arm], [turned]),
            ca.Function("lever_jacobian", [angles, arm], [ca.jacobian(turned, angles)]))


def lever_enu(angles: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """The lever arm turned by roll, pitch, yaw ``angles`` (n, 3) [rad], local ENU (n, 3) [m]."""
    turned = np.asarray(_lever()[0].map(len(angles))(angles.T, np.tile(arm[:, None], (1, len(angles))))).T
    return np.column_stack((turned[:, 1], turned[:, 0], -turned[:, 2]))


def lever_sigma(angles: np.ndarray, arm: np.ndarray, sigma: float) -> np.ndarray:
    """The lever arm's position sigma per ENU axis (n, 3) [m] from an attitude noise ``sigma`` [rad] per angle
    (linearized at ``angles``)."""
    jac = np.asarray(_lever()[1].map(len(angles))(angles.T, np.tile(arm[:, None], (1, len(angles)))))
    jac = jac.reshape(3, len(angles), 3)  # (NED row, instant, angle)
    ned = np.sqrt(np.sum(jac**2, axis=2)).T * sigma
    return ned[:, [1, 0, 2]]


def gnss_errors(times: np.ndarray, sigma: float, model: str, tau: float, rng: np.random.Generator) -> np.ndarray:
    """The platform's GNSS error per axis at increasing ``times`` [s]: white, or first-order Gauss-Markov
    discretized exactly between the instants (:mod:`sblsim.models.platform.core`), stationary start.

    Returns
    -------
    numpy.ndarray, shape (n, 3)
        ENU errors [m].
    """
    w = rng.standard_normal((len(times), 3))
    if model == "white":
        return sigma * w
    e = np.empty_like(w)
    e[0] = sigma * w[0]
    phi = np.exp(-np.diff(times) / tau)
    for k in range(1, len(times)):
        e[k] = phi[k - 1] * e[k - 1] + sigma * math.sqrt(1.0 - phi[k - 1] ** 2) * w[k]
    return e


@dataclass(frozen=True)
class Simulated:
    """One simulated survey (one replicate), one row per reply, local ENU [m].

    Attributes
    ----------
    t_tx, t_rx : numpy.ndarray, shape (n,)
        Transmit and receive times, POSIX [s].
    measured : Replies
        What the log records: the transducer from GNSS and measured attitude, its sigmas, the TWTT with noise.
    true : Replies
        The truth: the transducer's true positions, the same sigmas, the noise-free TWTT.
    truth, apriori : numpy.ndarray, shape (1, 3)
        The transponder's true and a-priori positions [m].
    twtt_sigma : float
        The TWTT's total noise std, turnaround jitter and measurement [s].
    sound_speed, assumed_sound_speed : float
        The true sound speed and the one the solver is told [m/s].
    ocean : numpy.ndarray, shape (n,)
        The moving ocean's delay of each TWTT [s] (0 in a still ocean): its nadir delay at the reply's mid-time
        and its gradient's part, over the legs' mean nadir cosine.
    ntd : numpy.ndarray, shape (n,)
        The nadir delay at each reply's mid-time [s].
    """

    t_tx: np.ndarray
    t_rx: np.ndarray
    measured: Replies
    true: Replies
    truth: np.ndarray
    apriori: np.ndarray
    twtt_sigma: float
    sound_speed: float
    assumed_sound_speed: float
    ocean: np.ndarray | None = None
    ntd: np.ndarray | None = None


def simulate(survey: Mapping[str, Any], platform: Mapping[str, Any], replicate: int = 0) -> Simulated:
    """Simulate one survey (module docstring).

    Parameters
    ----------
    survey : mapping
        The values of :data:`SURVEY_VARIABLES` (checked).
    platform : mapping
        The values of :data:`PLATFORM_KEYS` (checked; the platform's units).
    replicate : int
        The replicate (its streams: :func:`streams`).

    Returns
    -------
    Simulated
    """
    rng = streams(survey["seed"], replicate)
    c = float(survey["sound_speed_mps"])
    apriori = np.array([[0.0, 0.0, -float(survey["depth_m"])]])
    truth = apriori + survey["apriori_sigma_m"] * rng[_TRUTH].standard_normal((1, 3))
    x = truth[0]
    arm = np.array([0.0, 0.0, float(platform["transducer_depth"])])

    def antenna(t):
        return track(survey["pattern"], survey["radius_m"], survey["speed_mps"], t)

    def transducer(t):
        g, course = antenna(t)
        angles = np.column_stack((np.zeros_like(course), np.zeros_like(course), course))
        return g + lever_enu(angles, arm)

    t_tx = np.arange(0.0, survey["duration_s"] + 1e-9, survey["ping_period_s"])
    n = len(t_tx)
    p_tx = transducer(t_tx)
    leg_tx = np.linalg.norm(p_tx - x, axis=1)
    jitter = survey["turnaround_jitter_s"] * rng[_JITTER].standard_normal(n)
    t_reply = t_tx + leg_tx / c + survey["turnaround_s"] + jitter
    t_rx = t_reply + leg_tx / c
    for _ in range(60):  # the fixed point t_rx = t_reply + |p(t_rx) - x| / c (a contraction by speed / c)
        new = t_reply + np.linalg.norm(transducer(t_rx) - x, axis=1) / c
        done = np.max(np.abs(new - t_rx)) <= 1e-14 * max(1.0, float(np.max(t_rx)))
        t_rx = new
        if done:
            break
    p_rx = transducer(t_rx)
    leg_rx = np.linalg.norm(p_rx - x, axis=1)
    true_twtt = (leg_tx + leg_rx) / c
    twtt = true_twtt + jitter + survey["twtt_sigma_s"] * rng[_TWTT].standard_normal(n)
    ocean = ntd = np.zeros(n)
    gradient = np.array([survey["ntd_gradient_e_s"], survey["ntd_gradient_n_s"]])
    if survey["ntd_sigma_s"] > 0.0 or np.any(gradient != 0.0):  # a moving ocean: SeaGap's model of its delay
        mid = 0.5 * (t_tx + t_rx)
        ntd = ocean_delay(mid, survey["ntd_sigma_s"], survey["ntd_time_scale_s"], rng[_OCEAN])
        legs = (p_tx, p_rx)
        mapping = 0.5 * sum((p[:, 2] - x[2]) / np.linalg.norm(p - x, axis=1) for p in legs)
        slant = 0.5 * sum((x[:2] - p[:, :2]) / (p[:, 2] - x[2])[:, None] for p in legs)
        ocean = (ntd + slant @ gradient) / mapping
        twtt = twtt + ocean

    times = np.concatenate((t_tx, t_rx))
    order = np.argsort(times, kind="stable")
    gnss = np.empty((2 * n, 3))
    gnss[order] = gnss_errors(times[order], platform["gps_sigma"], platform["gps_model"], platform["gps_tau"],
                              rng[_GNSS])
    imu_sigma = math.radians(platform["imu_sigma_deg"])
    attitude_error = (math.radians(platform["imu_bias_deg"])
                      + imu_sigma * rng[_ATTITUDE].standard_normal((2 * n, 3)))
    g, course = antenna(times)
    angles = np.column_stack((np.zeros(2 * n), np.zeros(2 * n), course))
    measured = g + gnss + lever_enu(angles + attitude_error, arm)
    sigma = np.sqrt(platform["gps_sigma"] ** 2 + lever_sigma(angles, arm, imu_sigma) ** 2)
    sigma = np.maximum(sigma, SIGMA_FLOOR)
    ids = np.zeros(n, dtype=int)
    return Simulated(
        t_tx=EPOCH + t_tx, t_rx=EPOCH + t_rx,
        measured=Replies(measured[:n], sigma[:n], measured[n:], sigma[n:], twtt, ids, EPOCH + t_tx, EPOCH + t_rx),
        true=Replies(p_tx, sigma[:n], p_rx, sigma[n:], true_twtt, ids, EPOCH + t_tx, EPOCH + t_rx),
        truth=truth, apriori=apriori,
        twtt_sigma=math.hypot(survey["turnaround_jitter_s"], survey["twtt_sigma_s"]),
        sound_speed=c, assumed_sound_speed=c + survey["sound_speed_error_mps"], ocean=ocean, ntd=ntd)


__all__ = ["EPOCH", "GPS_MODELS", "OCEAN_TERMS", "PATTERNS", "PATTERN_POINTS", "PLATFORM_KEYS", "SIGMA_FLOOR",
           "SURVEY_VARIABLES", "Simulated", "gnss_errors", "lever_enu", "lever_sigma", "ocean_delay",
           "platform_variables", "simulate", "streams", "track"]
