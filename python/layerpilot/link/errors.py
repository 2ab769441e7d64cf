"""The flight link's exceptions: every one is a :class:`LinkError` whose message says what went wrong."""

from __future__ import annotations

from layerpilot.link import modes


class LinkError(RuntimeError):
    """The flight link could not do what was asked; the message says why."""


class LinkLost(LinkError):
    """No HEARTBEAT from the autopilot within the timeout."""


class NotReady(LinkError):
    """The vehicle did not become ready in time; ``missing`` lists what was still missing."""

    def __init__(self, message: str, missing: list[str]) -> None:
        super().__init__(message)
        self.missing = missing


class CommandRejected(LinkError):
    """The autopilot answered a command with something other than MAV_RESULT_ACCEPTED."""

    def __init__(self, command: int, result: int, detail: str = "") -> None:
        self.command, self.result = command, result
        self.result_name = modes.result_name(result)
        super().__init__(f"{modes.command_name(command)} rejected: {self.result_name}{detail}")


class ControlLost(LinkError):
    """A wait ended because the vehicle was taken over, failed safe, disarmed or rebooted; ``kind``
    says which (``takeover``, ``failsafe``, ``disarmed``, ``reboot``)."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


class WaypointRefused(LinkError, ValueError):
    """A waypoint outside the geofence (area or altitude), not finite, or too near another drone
    (``link.separation``); nothing was sent. ``kind``: ``not finite``, ``outside the area``, ``altitude``
    or ``separation``."""

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind
