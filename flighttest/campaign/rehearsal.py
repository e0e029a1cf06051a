"""What a ``--sim`` rehearsal changes on the fake autopilot: kept apart from the campaign loop so that
``flighttest campaign --help`` can name it without importing the loop (pandas and all)."""

from __future__ import annotations

from collections.abc import Mapping

# raised from PX4's 1.5 m/s for the rehearsal, so a descent faster than that (a sweep raised with
# --max-descent-speed, a catch-up beyond the plan) is not clipped by the fake: the README's parameter
# table asks the same of a real vehicle before faster sweeps
SIM_DEFAULT_PARAMS: Mapping[str, float] = {"MPC_Z_VEL_MAX_DN": 3.0}
# ArduCopter's defaults as they are: its plans fit them (the profile's [autopilot] limits) or the preflight says
SIM_DEFAULT_PARAMS_ARDUPILOT: Mapping[str, float] = {}


def px4_default(name: str) -> float:
    """PX4's own default of a parameter, as the fake holds it (``sitl_fakes.px4``)."""
    from sitl_fakes.px4 import default_params

    return float(default_params()[name].value)


def sim_param_help() -> str:
    """``--sim-param``'s help: what the rehearsal overrides against PX4's own defaults."""
    overrides = ", ".join(f"{k}={v:g} (PX4's default {px4_default(k):g})" for k, v in SIM_DEFAULT_PARAMS.items())
    return (f"a parameter of the fake's autopilot, repeatable. The PX4 fake starts with the rehearsal's "
            f"{overrides}; the ArduPilot fake with ArduCopter's defaults")  # fmt: skip
