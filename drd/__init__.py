"""drd: mission software for robot teams (daemon, mission executive, simulator and CLIs)."""

__version__ = "0.1.0"
