"""Whether the vehicle is on the ground, from evidence only.

The armed flag MAVSDK reports comes with the heartbeat (1 Hz on PX4 and ArduCopter), so for up to a
second after an arm is acknowledged it still reads "disarmed", and a flag delivered late can be older
still. A vehicle counts as on the ground only when, after the last arm or takeoff command was answered:

- it reported itself disarmed, and went on doing so for ``DISARM_HELD_S`` without a landed state that
  says it flies; or
- its landed state (EXTENDED_SYS_STATE) said "on the ground" for ``LANDED_HELD_S``.

Before any arm or takeoff command was sent, a vehicle that does not report itself armed never left it.
On the ground but armed (a takeoff stopped before the vehicle lifted: PX4 spools up for seconds and only
disarms by itself after a flight), the abort ladder disarms it (``flighttest.flying.guard.AbortLadder``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

DISARM_HELD_S = 1.0  # a second heartbeat confirms the first (one late report cannot)
# PX4's land detector says ON_GROUND about a second before it disarms (COM_DISARM_LAND 2 s); held this
# long it outlasts a takeoff's first tenths of a second, before the detector has seen the climb
LANDED_HELD_S = 3.0
AIRBORNE_STATES = frozenset({"IN_AIR", "TAKING_OFF", "LANDING"})


class ReportedState(Protocol):
    armed: bool
    t_armed: float | None
    armed_since_t: float | None
    landed_state: str
    t_landed: float | None
    landed_since_t: float | None


@dataclass
class GroundEvidence:
    """The arm and takeoff commands sent this flight, and the judgement they allow."""

    t_command_sent: float | None = None  # the last arm/takeoff command sent
    t_command_done: float | None = None  # … answered, refused or given up on
    commands_pending: int = 0

    def command_sent(self, t_s: float) -> None:
        self.t_command_sent = t_s
        self.commands_pending += 1

    def command_done(self, t_s: float) -> None:
        """The command was answered (or refused) at ``t_s``; or, given up on before its answer, ``t_s`` is the
        latest the vehicle could still act on it (the call goes on after its waiter is cancelled)."""
        self.t_command_done = t_s if self.t_command_done is None else max(self.t_command_done, t_s)
        self.commands_pending = max(self.commands_pending - 1, 0)

    def disarmed(self, st: ReportedState, now_s: float) -> str | None:
        """Why the vehicle is disarmed on the ground ("disarmed", "never armed"), or None without evidence."""
        if self.t_command_sent is None:
            return None if st.armed else "never armed"
        after = self._after(now_s)
        if (after is not None and not st.armed and st.t_armed is not None and st.t_armed > after
                and st.armed_since_t is not None and now_s - max(st.armed_since_t, after) >= DISARM_HELD_S
                and st.landed_state not in AIRBORNE_STATES):  # fmt: skip
            return "disarmed"
        return None

    def on_ground(self, st: ReportedState, now_s: float) -> str | None:
        """Why the vehicle is on the ground, armed or not ("disarmed", "never armed", "landed state on
        ground"), or None while there is no such evidence."""
        why = self.disarmed(st, now_s)
        if why is not None:
            return why
        after = self._after(now_s)
        if (after is not None and st.landed_state == "ON_GROUND" and st.t_landed is not None and st.t_landed > after
                and st.landed_since_t is not None
                and now_s - max(st.landed_since_t, after) >= LANDED_HELD_S):  # fmt: skip
            return "landed state on ground"
        return None

    def _after(self, now_s: float) -> float | None:
        """Evidence counts from here on; None while an arm or takeoff may still be acted on."""
        if self.commands_pending or self.t_command_done is None or now_s < self.t_command_done:
            return None
        return self.t_command_done
