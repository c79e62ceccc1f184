"""A receiver of your own: an EKF that assumes the diver stays where it is.

The state is the receivers' six-vector ``[x, vx, y, vy, z, vz]`` (NED); this
filter keeps the velocity at zero and lets the position wander as a random
walk of density ``q_position`` [m²/s]:

    x_k+1 = x_k,  P_k+1 = P_k + q_position · Δt  (position block)

and at every acoustic slot updates, one scalar after the other, with the
depth reading and with the fresh range of the transmitting beacon (none of
the held ranges). The measurement model, h and its casadi Jacobian, is the
one every Kalman-type receiver shares.

Run it with ``sblsim run semicircle --set receiver=model:constant_position.py``
(on either engine), compare it with ``sblsim compare semicircle --receivers
ekf-seq,model:constant_position.py``, and build its FMU with ``sblsim fmus
build --model constant_position.py``.
"""

import casadi as ca

from sblsim.models.declarations import Variable
from sblsim.models.receiver import KalmanReceiver, kalman
from sblsim.models.receiver.packets import fresh_range, take_packet


class ConstantPositionReceiver(KalmanReceiver):
    """Constant-position EKF: fresh range and depth, the position a random walk."""

    name = "receiver_constant_position"  # the FMU's name: receiver_...
    label = "constant-position"  # what plots and tables call it

    @classmethod
    def parameters(cls, n_beacons):
        return (
            Variable("sigma_range", "parameter", "Real", 0.1, "m", "Range standard deviation in R",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("sigma_depth", "parameter", "Real", 0.01, "m", "Depth standard deviation in R",
                     min=0.0, max=1000.0, min_exclusive=True),
            Variable("q_position", "parameter", "Real", 0.05, "m2/s", "Position random-walk density",
                     min=0.0, max=1e6),
            Variable("p0_position", "parameter", "Real", 1.0, "m", "Initial position standard deviation",
                     min=0.0, max=1e6, min_exclusive=True),
        ) + tuple(Variable(f"x0_{a}", "parameter", "Real", 0.0, "m", f"Initial position estimate, {a}",
                           min=-1e6, max=1e6) for a in "xyz")

    @classmethod
    def initial(cls, p):
        x0 = ca.vertcat(p["x0_x"], 0, p["x0_y"], 0, p["x0_z"], 0)
        return x0, ca.diag(ca.vertcat(*[p["p0_position"] ** 2, 0] * 3))

    @classmethod
    def predict(cls, x, P, h, p):
        return x, P + ca.diag(ca.vertcat(*[p["q_position"] * h, 0] * 3))

    @classmethod
    def correct(cls, x, u, p, n_beacons):
        fresh, rng, beacon = fresh_range(x, u, n_beacons)
        m = cls.measurement
        state, P, nis = kalman.scalar_update(x["x"], x["P"], u["depth"] - x["x"][4], m.depth_jacobian(),
                                             p["sigma_depth"] ** 2)
        h, H = m.range_row(state, beacon)
        S = ca.mtimes([H, P, H.T]) + p["sigma_range"] ** 2
        state, P, _ = kalman.scalar_update(state, P, rng - h, H, p["sigma_range"] ** 2, fresh)
        return {**take_packet(x, u, n_beacons), "x": state, "P": P,
                "nis": nis + ca.if_else(fresh, (rng - h) ** 2 / S, 0.0), "gated": 0, "failed": x["failed"]}
