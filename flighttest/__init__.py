"""flighttest: fast-descent flight tests that avoid the vortex ring and windmill-brake states."""

__version__ = "0.1.0"

__all__ = ["fly_mission", "fly_mission_async", "prepare_flight"]


def __getattr__(name: str):
    # the flying library is imported on first use: `flighttest --help` and the analysis need none of it
    if name in __all__:
        from flighttest.flying import mission

        return getattr(mission, name)
    raise AttributeError(f"module 'flighttest' has no attribute {name!r}")
