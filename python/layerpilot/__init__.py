"""layerpilot: autonomous survey drones that decide where to fly next."""

__version__ = "0.1.0"
