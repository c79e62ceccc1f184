"""The example of ``sblsim codegen receiver``: a recorded run's parameters, inputs and estimates as text files.

The generated C comes with what its README's run line reads: ``parameters.txt`` (the run's ``[receiver]``
parameters as ``NAME=VALUE`` arguments), ``packets.txt`` (one line ``t h inputs...`` per step) and
``expected.txt`` (the run's own estimates, ``t+h est_x est_y est_z``), so that a user sees at once that the
code on their device computes what ``sblsim run`` computed.

Time alignment (as for a receiver FMU fed recorded data): the row the time series records at t_k holds the
packet the receiver used in its step from t_(k−1) to t_k.
"""

from __future__ import annotations

from sblsim.models import MODELS, RECEIVERS
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.cosim.run import run

#: The recorded run: the semicircle's first 20 s at seed 1, with 10 % packet loss so that lost slots show.
EXAMPLE = ("semicircle", ["simulation.duration=20", "acoustics.loss_pct=10"], 1)


def example_files(receiver: str, system: str | None = None) -> tuple[dict[str, str], str, int]:
    """The example files of a built-in receiver and the README paragraph that says what they are.

    Parameters
    ----------
    receiver : str
        A built-in receiver.
    system : str, optional
        The positioning system of the recorded run (``platform.system``, one of
        :data:`sblsim.models.systems.SYSTEMS`; default, or the first of them: the scenario's).

    Returns
    -------
    files : dict
        ``parameters.txt``, ``packets.txt``, ``expected.txt`` -> their text.
    about : str
    n_beacons : int
        The size of the receiver's interface (1 for USBL).
    """
    scenario, overrides, seed = EXAMPLE
    if system is not None and system != next(iter(SYSTEMS)):  # the scenario's own is the first
        overrides = [*overrides, f"platform.system={system}"]
    plan = load_plan(scenario, [*overrides, f"simulation.receiver={receiver}"], seed=seed)
    series = run(plan).timeseries
    model = MODELS[RECEIVERS[receiver]]
    n_beacons = plan.n_beacons
    params = plan.component_parameters("receiver")  # the [receiver] section and what the orchestrator sets (the clock)
    seeds = {"seed", "scenario_key", "cell", "replicate"}
    inputs = [v.name for v in model.inputs(n_beacons)]
    T = plan.sampling_time
    # (a later lane of a delivery the run never used is not in its time series: empty, packet_seq 0)
    packets = [" ".join(repr(float(x)) for x in [k * T, T, *(getattr(row, n, 0.0) for n in inputs)])
               for k, row in enumerate(series.itertuples(index=False))]
    expected = [" ".join(repr(float(getattr(row, c))) for c in ("time", "est_x", "est_y", "est_z"))
                for row in series.itertuples(index=False)]
    choices = {v.name: v.choices for v in model.fmu_parameters_declared(n_beacons) if v.choices is not None}
    params = {k: (choices[k].index(v) if k in choices and isinstance(v, str) else v) for k, v in params.items()}
    files = {"parameters.txt": " ".join(f"{k}={v!r}" for k, v in params.items() if k not in seeds) + "\n",
             "packets.txt": "\n".join(packets) + "\n", "expected.txt": "\n".join(expected) + "\n"}
    about = (f"The example files are a recorded run (`sblsim run {scenario} --seed {seed} "
             f"{' '.join('--set ' + o for o in overrides)} --set receiver={receiver}`): its parameters "
             "(`parameters.txt`), the receiver's inputs at every step (`packets.txt`) and the run's own estimates "
             "(`expected.txt`); `estimates.txt` equals `expected.txt` to about 1e-12 m.\n")
    return files, about, n_beacons


__all__ = ["EXAMPLE", "example_files"]
