"""The link node: waypoints from the bus to a MAVLink autopilot, the vehicle's pose back to the bus.

At start it connects, waits until the autopilot is ready, takes control (GUIDED /
OFFBOARD), arms and climbs to ``takeoff_altitude``; then every waypoint becomes a
setpoint and the pose is published at ``pose_rate`` (only once the autopilot has a
position: no (0, 0, 0) pose before the first LOCAL_POSITION_NED). When the node stops
(SIGTERM, Ctrl-C, `up --duration`, or a failure) it commands the mission's end action
(``end_action``: RTL, LAND or LOITER) and waits up to ``end_timeout`` for the autopilot to
acknowledge it, so an armed vehicle is never left in GUIDED with nothing supervising it. A reboot of the
autopilot (told apart from a pilot takeover by the link) ends the flying (``on_reboot = "end"``) or
pauses it until a pilot has the vehicle armed, airborne and in GUIDED again (``"pause"``). When the
pilot turns home for the battery (the mission state's phase ``return: battery``) the node commands
RTL at once: the autopilot flies home and lands, and the mission's end leaves it so. When the
autopilot's own battery failsafe took the vehicle home (``link.failsafe``: not a takeover) the
node ends the mission the same way, leaving the autopilot's RTL alone. Pose stamps are the
autopilot's clock (time_boot_ms) on the mission clock (mission.clock: + the saved mission time
when a survey resumes): the simulator node stamps its camera frames, and so the clouds and layer
sets, with the same clock, at any speed; in camera-only mode the frames take the pose's stamp. A
reboot in flight moves the node's mission clock on by the uptime the autopilot had (its clock counts
from 0 again), so the stamps never go back.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence

import zenoh

from layerpilot.bus import keys
from layerpilot.bus.guard import guarded
from layerpilot.bus.messages import (MissionState, State, Waypoint, decode_decision, decode_mission_state,
                                     decode_state, decode_waypoint, encode_state)
from layerpilot.bus.reject import BadMessage, Rejects
from layerpilot.bus.session import publish
from layerpilot.geometry import Pose
from layerpilot.link.geofence import Geofence
from layerpilot.link.link import FlightLink, LinkError, WaypointRefused
from layerpilot.link.separation import Separation
from layerpilot.mission.clock import MissionClock
from layerpilot.missionfile import LinkSettings
from layerpilot.mission.energy import RETURN_PHASE
from layerpilot.link.modes import GUIDED_MODE
from layerpilot.nodes.runner import WAKE_PERIOD, wait_for_stop
from layerpilot.nodes.supervise import Supervisor

_log = logging.getLogger("layerpilot.link")


class LinkNode:
    """``geofence``: the mission's (``missionfile.geofence_for``); the link refuses every waypoint
    outside it, and each refusal is logged once per kind and counted in ``rejects``.

    ``connected`` is set once the autopilot's HEARTBEAT was heard (the node says ``ready`` then,
    ``connecting`` before); ``phase`` is ``connecting``, ``waiting for the autopilot``, ``taking off``,
    ``flying``, ``returning home ...`` (a battery return: the pilot's or the autopilot's failsafe),
    ``ended: autopilot rebooted`` or ``paused: autopilot rebooted ...`` (``on_reboot``),
    ``ending`` or ``ended``; a link that cannot connect or take off fails the node
    (``supervisor.failure`` says why). ``end`` says what the end action did (see :meth:`stop`)."""

    def __init__(self, session: zenoh.Session, vehicle: str, cfg: LinkSettings, geofence: Geofence,
                 mission_clock: MissionClock = MissionClock(), fleet: Sequence[str] = ()) -> None:
        """``fleet``: the mission's vehicles; with others than this one (and ``cfg.separation`` > 0) the
        link hears their poses and decisions and refuses a waypoint nearer them than the separation."""
        self.session, self.keys, self.cfg = session, keys.Keys(vehicle), cfg
        self.fleet = tuple(v for v in fleet if v != vehicle)
        self.mission_clock = mission_clock  # pose stamps: the autopilot's time_boot_ms on the mission clock
        self.rejects = Rejects(_log)
        self.supervisor = Supervisor(_log)
        self.connected = threading.Event()
        self.phase = "connecting"
        self._t0 = time.monotonic()
        self.separation = (Separation(cfg.separation, cfg.separation_stale_s) if self.fleet and cfg.separation > 0
                           else None)
        self.link = FlightLink(cfg.link, clock=self.clock, geofence=geofence, separation=self.separation)
        self._stop = threading.Event()
        self._sub = None
        self._state_sub = None
        self._fleet_subs: list = []
        self.homeward = threading.Event()  # the pilot turned home for the battery: RTL
        self.waypoints = 0
        self._last_seq = -1
        self._speed = 0.0  # m/s last asked of the autopilot; 0 = its default
        self.end = ""  # what the mission's end action did, once the node stops
        self.poses = 0
        self._held: tuple[Waypoint, str] | None = None  # the newest waypoint heard while paused after a reboot
        self._interrupter: threading.Thread | None = None
        self._clock_reboots = 0  # reboots the mission clock was moved on for
        self.rtl_refusals = 0  # battery RTLs not acknowledged (each tried again at the next wake)

    def clock(self) -> float:
        return time.monotonic() - self._t0

    def run(self, stop: threading.Event) -> None:
        """Connect, take off, then follow waypoints until ``stop``; a stop during the takeoff aborts it."""
        # a stop ends the link's waits but keeps its connection: stop() still commands the end action
        self._interrupter = threading.Thread(target=lambda: (stop.wait(), self.link.interrupt()), daemon=True)
        self._interrupter.start()
        link = self.link
        try:
            link.connect()
            self.connected.set()
            self.phase = "waiting for the autopilot"
            self.supervisor.start("link-pose", self._publish_pose)  # from now on, so the ground sees the takeoff
            link.wait_ready()
            self.phase = "taking off"
            link.start_guided()
            link.arm()
            link.takeoff(self.cfg.takeoff_altitude)
        except LinkError as exc:
            if not stop.is_set():  # the waits end with an error when the link is closed
                self.supervisor.fail(f"{self.phase}: {exc}")  # the node exits 1, `up` restarts it
                self.phase = "failed"
            return
        self._sub = self.session.declare_subscriber(self.keys.waypoint,
                                                    guarded(decode_waypoint, self._on_waypoint, self.rejects,
                                                            self.supervisor))
        self._state_sub = self.session.declare_subscriber(self.keys.state, guarded(
            decode_mission_state, self._on_mission_state, self.rejects, self.supervisor))
        if self.separation is not None:  # the other drones: where they are and where they go
            self._fleet_subs = [
                self.session.declare_subscriber(keys.all_vehicles("pose"), guarded(
                    decode_state, lambda s, key: self._on_other(key, s.vehicle, position=s.position), self.rejects,
                    self.supervisor)),
                self.session.declare_subscriber(keys.all_vehicles("decision"), guarded(
                    decode_decision, lambda d, key: self._on_other(key, d.vehicle, target=d.waypoint), self.rejects,
                    self.supervisor))]
        self.phase = "flying"  # listening: a waypoint heard before is held, and decide repeats it
        self._watch(stop)

    def _on_other(self, key: str, vehicle: str, position=None, target=None) -> None:
        """Another drone's pose or decision, for the separation; this vehicle's own are not news."""
        sender = keys.vehicle_of(key)
        if sender == self.keys.vehicle:
            return
        if sender not in self.fleet or vehicle != sender:
            raise BadMessage("unknown vehicle", f"{vehicle!r} on {key}: not one of the mission's other vehicles "
                                                f"{list(self.fleet)}")
        self.separation.heard(sender, position, target)

    def _on_mission_state(self, s: MissionState, key: str) -> None:
        if s.phase == RETURN_PHASE:
            self.homeward.set()

    def _watch(self, stop: threading.Event) -> None:
        """Until ``stop``: a battery return commands RTL; after a reboot (the vehicle is disarmed on the
        ground) the flying ends, or with ``on_reboot = "pause"`` waits until a pilot has it armed, airborne
        and in GUIDED again, then goes on with the newest waypoint. A takeover is the link's own pause."""
        reboots = self.link.reboots
        while not stop.wait(WAKE_PERIOD):
            if self.homeward.is_set() and self.phase == "flying":
                self._return_home()
            if self.link.failsafe and self.phase == "flying" and self.link.paused:  # the autopilot's own return
                self.phase = f"returning home: {self.link.failsafe}"
                _log.warning("%s; the mission's end leaves it so", self.phase)
            elif self.phase.startswith("returning home: ") and not self.link.paused and self._guided_again():
                self.phase = "flying"  # a pilot handed GUIDED back after the failsafe: the link flies it again
                _log.warning("GUIDED handed back after the autopilot's return: flying again; the mission's end "
                             "commands %s", self.cfg.end_action)
            if self.link.reboots == reboots:
                continue
            reboots = self.link.reboots
            if self.cfg.on_reboot == "end":
                self.phase = "ended: autopilot rebooted"
                _log.warning("the autopilot rebooted: the mission's flying ends (link.on_reboot = end)")
                wait_for_stop(stop)
                return
            guided = GUIDED_MODE[self.link.flavour]
            self.phase = f"paused: autopilot rebooted; waiting for a pilot to arm, take off and hand over {guided}"
            _log.warning("the autopilot rebooted: %s (link.on_reboot = pause)", self.phase)
            while not stop.wait(WAKE_PERIOD) and self.link.reboots == reboots and not self._flying_again(guided):
                pass
            if self.link.reboots == reboots and not stop.is_set():
                self._resume()

    def _return_home(self) -> None:
        """RTL for the battery; only an acknowledged RTL is a return (``stop`` then leaves it so): a refused
        or unanswered one is tried again at the next wake, and the mission's end still commands its action."""
        ok, self.end = self.link.end_mission("rtl", self.cfg.end_timeout)
        if ok:
            self.phase = f"returning home for the battery: {self.end}"
            _log.warning("%s", self.phase)
            return
        self.rtl_refusals += 1
        if self.rtl_refusals == 1:
            _log.warning("battery return: %s; trying again (the mission's end still commands %s)", self.end,
                         self.cfg.end_action)

    def _guided_again(self) -> bool:
        """The vehicle is back in GUIDED, armed (a pilot handed it back after an RTL): nothing else supervises it."""
        t = self.link.telemetry()
        return t.armed and t.mode == GUIDED_MODE.get(self.link.flavour)

    def _flying_again(self, guided: str) -> bool:
        t = self.link.telemetry()
        return (t.armed and t.mode == guided and self.link.position_valid and t.home is not None
                and t.position[2] - t.home[2] > 1.0)

    def _resume(self) -> None:
        try:
            self.link.start_guided()
        except LinkError as exc:
            _log.warning("could not take control again after the reboot: %s", exc)
            return
        self.phase, held, self._held, self._last_seq = "flying", self._held, None, -1
        _log.warning("flying again after the reboot: control handed over in %s", self.link.mode)
        if held is not None:
            self._on_waypoint(*held)

    def _on_waypoint(self, w: Waypoint, key: str) -> None:
        if self.phase != "flying":  # paused after a reboot: the newest waypoint flies once control is back
            self._held = (w, key)
            return
        if w.seq == self._last_seq:  # decide repeats its current waypoint until reached
            return
        self._last_seq = w.seq
        try:
            self.link.check_waypoint(*w.position)  # the geofence first: nothing of a refused waypoint is sent
            if w.speed != self._speed:  # a survey pattern flies at the speed its camera rate allows
                self.link.set_speed(w.speed if w.speed > 0 else None)
                self._speed = w.speed
            self.link.set_waypoint(*w.position, yaw=None if math.isnan(w.yaw) else w.yaw, face_waypoint=True)
            self.waypoints += 1
        except WaypointRefused as exc:  # outside the geofence (area, altitude), not finite, or too near a drone
            self.rejects.reject(key, BadMessage(f"waypoint refused ({exc.kind})", str(exc)))
            if exc.kind == "separation":  # decide's repeat tries it again: the other drone moves on
                self._last_seq = -1
        except (LinkError, ValueError) as exc:  # the pilot has the vehicle, the link is lost
            self.rejects.reject(key, BadMessage("waypoint refused", str(exc)))

    def _publish_pose(self) -> bool:
        """One pose at ``pose_rate`` (a supervised loop: an error is counted, the next pose goes out)."""
        if self._stop.wait(1.0 / self.cfg.pose_rate):
            return False
        cut = self.link.uptimes_before_reboot
        if len(cut) > self._clock_reboots:  # the autopilot's clock restarted at 0: the mission's goes on
            for uptime in cut[self._clock_reboots:]:
                self.mission_clock = self.mission_clock.after_reboot(uptime)
            self._clock_reboots = len(cut)
        if not self.link.position_valid:  # (0, 0, 0) before the autopilot's first position is no pose
            return True
        t = self.link.telemetry()
        if len(cut) != self._clock_reboots or not self.link.position_valid:  # a reboot meanwhile: the next one
            return True
        if t.link_ok:
            battery = t.battery_remaining / 100.0 if 0 <= t.battery_remaining <= 100 else math.nan
            publish(self.session, self.keys.pose, encode_state(State(
                self.mission_clock(t.boot_time), self.keys.vehicle,
                Pose.from_euler(t.roll, t.pitch, t.yaw, t.position), t.velocity,
                t.armed, t.mode, battery)))
            self.poses += 1
        return True

    def pose_state(self) -> str:
        """For the status line: whether poses go out, or what they wait for."""
        if self.link.flavour is None:
            return "waiting for the autopilot"
        if not self.link.position_valid:
            return "waiting for a position (LOCAL_POSITION_NED" + \
                (", EKF)" if "EKF" in " ".join(self.link.missing()) else ")")
        return "publishing"

    def stop(self) -> None:
        """No more waypoints, then the mission's end action (``end_action``, bounded by ``end_timeout``),
        then close the link. ``end`` says what happened (``RTL acknowledged ...`` or why not)."""
        self._stop.set()
        for sub in (self._sub, self._state_sub, *self._fleet_subs):
            if sub is not None:
                sub.undeclare()
        self.supervisor.join()
        if self._interrupter is not None:
            self._interrupter.join(timeout=1.0)  # its interrupt() lands before the end action clears it
        # an RTL for the battery stays (the autopilot flies home and lands) unless a pilot handed GUIDED back
        homeward = self.phase.startswith("returning home") and not self._guided_again()
        failed, self.phase = self.phase == "failed", "ending"
        if not homeward:
            _, self.end = self.link.end_mission(self.cfg.end_action, self.cfg.end_timeout)
        self.phase = "failed" if failed else "ended"
        self.link.close()
