"""The warnings ``sblsim run`` prints after a run's metrics: what its numbers do not say by themselves (a receiver
that never made a fix, exchanges heard into the next slot, a diver beyond what the geometry serves).
"""

from __future__ import annotations

from sblsim.orchestrator.cosim.metrics import REACH_RATIO


def _run_warnings(s: dict, plan) -> list[str]:
    """What a run's numbers do not say by themselves: a receiver that never made a fix, exchanges heard into the
    next slot, and a diver beyond what the geometry serves (:func:`sblsim.orchestrator.cosim.metrics.run_flags`)."""
    out = []
    if s["updates"] == 0:
        out.append(f"the {s['receiver']} receiver never made a fix: no slot of the run brought a range it used "
                   "(every packet lost or gated); it has no estimate and its error metrics no value "
                   "(summary.json: updates = 0)")
    elif s["fix_steps"] == 0 and plan.latency_steps > 0:
        # the record shows what the diver sees: the receiver's outputs receiver.latency late
        latency = f"receiver.latency = {plan['receiver']['latency']:g} s"
        if plan.latency_steps >= s["steps"]:
            what = (f"{latency} is as long as the run: the diver never sees an output the receiver computed from a "
                    f"packet (no recorded step has an estimate), though it used {s['updates']} ranges")
        else:
            what = (f"no multilateration fix reached the diver within the run (none was made, or {latency} delayed "
                    "every one past its end)")
        out.append(f"{what}; the instr_ metrics have no value (summary.json: fix_steps = 0 counts the steps the "
                   "diver saw a fix)")
    elif s["fix_steps"] == 0:
        out.append("no multilateration fix was ever made (never ranges of three beacons): the instr_ metrics have "
                   "no value, and a receiver that reports that fix (lsq) has no estimate "
                   "(summary.json: fix_steps = 0)")
    if s.get("slot_overrun"):
        out.append(f"an exchange was still heard {s['slot_overrun']:.4g} s after its slot began (its last arrival, "
                   f"multipath included), beyond simulation.sampling_time = {plan.sampling_time:g} s: the next "
                   "slot's packet overlaps it, which the channel does not model; give a sampling time of at least "
                   f"{s['slot_overrun']:.4g} s (summary.json: slot_overrun)")
    if s["beyond_geometry"]:
        spread = plan.horizontal_spread
        ratio = f"{s['max_distance'] / spread:.0f} times" if spread > 0 else "infinitely many times"
        bound = "n/a" if s["pcrb_rms"] is None else f"{s['pcrb_rms']:.3f}"
        out.append(f"the diver went {s['max_distance']:.6g} m from the platform, {ratio} the beacons' horizontal "
                   f"spread ({spread:.4g} m; the geometry serves up to {REACH_RATIO:g} times): the errors are the "
                   f"system's real accuracy there (PCRB RMS {bound} m), not a divergence "
                   "(summary.json: beyond_geometry)")
    return out
