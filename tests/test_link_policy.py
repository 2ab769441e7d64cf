"""The flight link's state tracker and failsafe policy fed real MAVLink bytes, without a vehicle:
where a reboot starts (the uptime's step back) and what tells the autopilot's battery failsafe
from a pilot's takeover. The end-to-end behaviour is test_link_reboot.py's and
test_battery_resume.py's."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link.commands import Commands
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import MavlinkPort
from layerpilot.link.control import Control
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import VehicleState

CONFIG = LinkConfig(url="tcp:127.0.0.1:1")  # nobody listens: the commands the policy sends are dropped
GUIDED, RTL = 4, 6                          # ArduCopter custom_mode numbers


def wire(msg, system: int = 1, component: int = 1):
    """``msg`` as the link receives it: packed by a MAVLink 2 encoder as (system, component), decoded."""
    return mav.MAVLink(None).decode(bytearray(msg.pack(mav.MAVLink(None, srcSystem=system, srcComponent=component))))


def heartbeat(custom_mode: int, armed: bool = True):
    return wire(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                              mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0, custom_mode, 4, 3))


def attitude(uptime_s: float):
    return wire(mav.MAVLink_attitude_message(int(uptime_s * 1000), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


@pytest.fixture
def parts():
    sync = LinkSync()
    port = MavlinkPort(CONFIG.url, CONFIG.source_system, CONFIG.source_component, CONFIG.baud)
    state = VehicleState(CONFIG, lambda: 0.0, sync)
    control = Control(CONFIG, state, Commands(CONFIG, state, port, sync), sync)
    assert state.identify(heartbeat(GUIDED)) and state.flavour == "ardupilot"
    control.on_heartbeat(state.on_heartbeat(heartbeat(GUIDED)))
    control.in_control = True
    yield state, control, sync
    port.close()


def test_an_uptime_step_back_over_a_second_is_a_reboot_and_jitter_is_not(parts):
    state, control, sync = parts
    state.home = state.position.copy()
    assert state.update(attitude(100.0)) is None
    assert state.update(attitude(99.2)) is None  # 0.8 s back: reordered or jittery readings, not a reboot
    assert state.home is not None
    before = state.update(attitude(3.0))
    assert before == pytest.approx(99.2)
    assert state.home is None and not state.position_valid and not state.prearm_ok  # told again after a boot
    with sync.cond:  # the worker holds the link's lock while it hands on what it received
        text = control.on_reboot(before, state.uptime)
    assert text == ("autopilot rebooted: its uptime went back from 99.2 s to 3.0 s; ARMED in GUIDED; "
                    "the link let go of the vehicle")
    assert (control.reboots, control.uptimes_before_reboot) == (1, [pytest.approx(99.2)])
    assert not control.in_control and control.upsets == [("reboot", text)]


def test_a_mode_change_after_a_low_battery_text_is_the_autopilots_failsafe_not_a_takeover(parts):
    state, control, _ = parts
    state.update(wire(mav.MAVLink_statustext_message(mav.MAV_SEVERITY_CRITICAL, b"Battery 1 is low 14.10V used 900 mAh")))
    reports = control.on_heartbeat(state.on_heartbeat(heartbeat(RTL)))
    assert reports == ["autopilot failsafe: battery (Battery 1 is low 14.10V used 900 mAh): RTL"]
    assert control.failsafe == reports[0] and control.upsets[-1][0] == "failsafe" and control.paused


def test_a_mode_change_without_one_is_a_takeover_until_guided_is_handed_back(parts):
    state, control, _ = parts
    reports = control.on_heartbeat(state.on_heartbeat(heartbeat(RTL)))
    assert reports == ["pilot took over: mode RTL; paused until GUIDED is handed back"]
    assert control.failsafe == "" and control.upsets[-1][0] == "takeover" and control.paused
    assert control.on_heartbeat(state.on_heartbeat(heartbeat(GUIDED))) == ["control handed back (GUIDED); resuming"]
    assert not control.paused and control.in_control
