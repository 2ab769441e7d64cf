"""Issue 14, items 1 and 3, on the simulated ArduCopter, which - like the real one - streams only
HEARTBEAT until asked and forgets what was asked when it reboots: a reboot in flight behind a link
loss (the SITL killed and restarted under `link goto`) is reported as a reboot, not a disarm; and
readiness waits for the GPS fix and the EKF, whose messages the link asks for."""

from __future__ import annotations

import threading
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import wait_for
from test_link_flight import FAST, url_of, vehicle  # noqa: F401 (fixture)
from layerpilot.cli import main as cli_main
from layerpilot.link.config import LinkConfig
from layerpilot.link.link import FlightLink, NotReady
from layerpilot.sim.mavlink_vehicle import EKF_FLAGS_NO_GPS, MavlinkVehicle


def test_a_reboot_behind_a_link_loss_during_link_goto_is_a_reboot(vehicle: MavlinkVehicle, capsys):
    """The real SITL killed 6 s into `link goto` and restarted: the link is lost for more than its
    heartbeat timeout, then a disarmed autopilot that streams nothing answers. Before the fix the
    disarm was judged 0.3 s later, with no uptime heard: "disarmed while the link was flying it"."""
    url = url_of(vehicle)
    assert cli_main(["link", "--mavlink", url, "takeoff", "12"]) == 0

    def restart_on_the_way() -> None:
        wait_for(lambda: vehicle.pose().position[0] > 5.0, "the flight to start")
        vehicle.pause_output()          # killed: silent past the link's 3 s heartbeat timeout
        time.sleep(3.5)
        vehicle.reboot()                # restarted: disarmed on the ground, no streams
        vehicle.resume_output()

    restarter = threading.Thread(target=restart_on_the_way)
    restarter.start()
    assert cli_main(["link", "--mavlink", url, "--timeout", "60", "goto", "110", "0", "15"]) == 1
    restarter.join()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("layerpilot link goto: error: goto: autopilot rebooted: its uptime "
                                               "went back from "), err


def test_readiness_waits_for_the_gps_fix_and_the_ekf(vehicle: MavlinkVehicle):
    """Pre-arm bit, position and home all there, but GPS_RAW_INT says 2D fix and EKF_STATUS_REPORT has no
    horizontal position: not ready, naming both, until they turn good."""
    withheld = threading.Event()
    withheld.set()
    real_gps, real_ekf = vehicle.telemetry.gps_raw_int, vehicle.telemetry.ekf_status_report
    vehicle.telemetry.gps_raw_int = lambda: vehicle.port.mav.gps_raw_int_send(
        0, mav.GPS_FIX_TYPE_2D_FIX, 0, 0, 0, 65535, 65535, 0, 65535, 4) if withheld.is_set() else real_gps()
    vehicle.telemetry.ekf_status_report = lambda: vehicle.port.mav.ekf_status_report_send(
        EKF_FLAGS_NO_GPS, 0.0, 0.0, 0.0, 0.02, 0.0) if withheld.is_set() else real_ekf()
    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST), clock=lambda: vehicle.time) as link:
        link.connect(5.0)
        with pytest.raises(NotReady) as info:
            link.wait_ready(timeout=1.5)   # 15 mission s: pre-arm (2 s), position and home long there
        assert info.value.missing == ["GPS 3D fix (fix_type 2)", f"EKF position (EKF_STATUS_REPORT flags "
                                                                 f"0x{EKF_FLAGS_NO_GPS:x})"], info.value.missing
        withheld.clear()
        link.wait_ready(timeout=10.0)
        assert link.missing() == []
