"""A user's own receiver, written the way a user outside sblsim would write one.

It knows nothing of sblsim: it declares the receiver interface (the same
names, causalities and units as sblsim's EKF), and estimates the diver's
position from each new range and the depth alone: straight below the
horizontal circle of radius sqrt(r² − Δz²) around the transmitting beacon,
at the point of that circle nearest to the previous estimate. The velocity
is the difference of consecutive estimates. It claims a fixed covariance.

Built with ``pythonfmu build -f user_receiver.py``; pythonfmu writes no
units, so ``RealWithUnit`` adds the ``unit`` attribute itself.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Slave
from pythonfmu.variables import Boolean, Integer, Real


class RealWithUnit(Real):
    def __init__(self, name, unit, **kwargs):
        super().__init__(name, **kwargs)
        self.unit = unit

    def to_xml(self):
        element = super().to_xml()
        element.find("Real").set("unit", self.unit)
        return element


INPUTS = [("packet_seq", "Integer", ""), ("beacon_id", "Integer", ""), ("packet_valid", "Boolean", ""),
          ("tx_time", "Real", "s"), ("range", "Real", "m"), ("beacon_x", "Real", "m"),
          ("beacon_y", "Real", "m"), ("beacon_z", "Real", "m"), ("depth", "Real", "m"), ("rx_time", "Real", "s")]
OUTPUTS = [("est_x", "Real", "m"), ("est_y", "Real", "m"), ("est_z", "Real", "m"),
           ("est_vx", "Real", "m/s"), ("est_vy", "Real", "m/s"), ("est_vz", "Real", "m/s"),
           ("instr_x", "Real", "m"), ("instr_y", "Real", "m"), ("instr_z", "Real", "m"),
           ("instr_valid", "Boolean", ""), ("nis", "Real", "1"), ("pos_std", "Real", "m"),
           ("cov_xx", "Real", "m2"), ("cov_xy", "Real", "m2"), ("cov_xz", "Real", "m2"),
           ("cov_yy", "Real", "m2"), ("cov_yz", "Real", "m2"), ("cov_zz", "Real", "m2"), ("gated", "Boolean", "")]
#: The accuracy it claims, fixed: 1 m horizontally, 1 cm in depth [m²].
COVARIANCE = {"cov_xx": 1.0, "cov_yy": 1.0, "cov_zz": 1e-4}


class UserReceiver(Fmi2Slave):
    author = "a user"
    description = "Range-and-depth projection receiver"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for name, kind, unit in INPUTS + OUTPUTS:
            setattr(self, name, 0 if kind == "Integer" else (False if kind == "Boolean" else 0.0))
            causality = Fmi2Causality.input if (name, kind, unit) in INPUTS else Fmi2Causality.output
            if kind == "Real":
                self.register_variable(RealWithUnit(name, unit, causality=causality))
            else:
                self.register_variable({"Integer": Integer, "Boolean": Boolean}[kind](name, causality=causality))
        self.last_seq = 0
        for name, value in COVARIANCE.items():
            setattr(self, name, value)
        self.pos_std = math.sqrt(sum(COVARIANCE.values()))

    def do_step(self, current_time, step_size):
        # a new packet that has arrived by the end of the step
        if self.packet_seq != self.last_seq and current_time + step_size >= self.rx_time - 1e-9 and self.packet_valid:
            dz = self.depth - self.beacon_z
            radius = math.sqrt(max(self.range ** 2 - dz ** 2, 0.0))
            dx, dy = self.est_x - self.beacon_x, self.est_y - self.beacon_y
            norm = math.hypot(dx, dy) or 1.0
            x, y = self.beacon_x + radius * dx / norm, self.beacon_y + radius * dy / norm
            self.est_vx, self.est_vy = (x - self.est_x) / step_size, (y - self.est_y) / step_size
            self.est_vz = (self.depth - self.est_z) / step_size
            self.est_x, self.est_y, self.est_z = x, y, self.depth
            self.instr_x, self.instr_y, self.instr_z = x, y, self.depth
            self.instr_valid = True
        if current_time + step_size >= self.rx_time - 1e-9:
            self.last_seq = self.packet_seq
        return True
