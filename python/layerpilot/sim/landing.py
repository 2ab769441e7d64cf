"""RTL and LAND as ArduCopter flies them: climb to RTL_ALT, return above home, descend slowing near the ground."""

from __future__ import annotations

import numpy as np

from layerpilot.sim.autopilot_state import AutopilotState


class Landing:
    """Steers the vehicle through RTL's phases (``state.rtl_phase``) and the landing descent, one step at a time."""

    def __init__(self, state: AutopilotState) -> None:
        self._s = state

    def rtl(self) -> None:
        """One step of RTL: climb to ``rtl_alt_m`` above home if lower, fly back above home, then land."""
        s = self._s
        v, home = s.vehicle, s.home
        if s.rtl_phase == "climb":
            alt = max(v.position[2], home[2] + s.config.rtl_alt_m)
            v.set_position_target(v.position[0], v.position[1], alt)
            if v.position[2] >= alt - 0.3:
                s.rtl_phase = "return"
        if s.rtl_phase == "return":
            v.set_position_target(home[0], home[1])
            if np.hypot(*(v.position[:2] - home[:2])) < 0.5 and np.linalg.norm(v.velocity[:2]) < 0.3:
                s.rtl_phase = "land"
        if s.rtl_phase == "land":
            self.descend()

    def descend(self) -> None:
        """Down at the airframe's descent limit, at LAND_SPEED below ``land_slow_below_m``."""
        v, cfg = self._s.vehicle, self._s.config
        height = v.position[2] - v.ground_z
        speed = cfg.land_speed_m_s if height < cfg.land_slow_below_m else v.limits.max_speed_down
        v.set_velocity_target(0.0, 0.0, -speed)
