"""flighttest: fast-descent flight tests that avoid the vortex ring and windmill-brake states."""

__version__ = "0.1.0"
