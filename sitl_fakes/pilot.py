"""A pilot's transmitter for the ArduCopter personality: a test hook that takes over the way a pilot does.

ArduCopter changes mode when its mode-switch channel (FLTMODE_CH, 5) moves to a new position (FLTMODE1..6),
and takes stick input from RC_CHANNELS_OVERRIDE — only from its ground station's sysid (MAV_GCS_SYSID,
255), and only while the overrides keep coming (RC_OVERRIDE_TIME, 3 s; after that the channels fall back
to the SITL transmitter: mode switch on FLTMODE6 = STABILIZE, throttle low). ``Pilot`` is that ground
station: a pymavlink peer at sysid 255 that sends HEARTBEAT and RC_CHANNELS_OVERRIDE at ``rate_hz`` from a
background thread, sticks centred (throttle mid: LOITER / ALT_HOLD / POSHOLD hold their height,
STABILIZE hovers).

    with fake.pilot() as pilot:          # FakeVehicle(..., autopilot="ardupilot").pilot()
        pilot.switch("LOITER")           # or ALT_HOLD, POSHOLD, STABILIZE, … (any ArduCopter mode name)
        pilot.sticks(throttle=1300)      # descend

``switch`` writes the mode into FLTMODE1 or FLTMODE2 (whichever the switch is not on; PARAM_SET, echoed)
and moves the switch there, so any mode is one call away. Closing the pilot stops its heartbeats — with
FS_GCS_ENABLE set, the fake's GCS failsafe then fires after FS_GCS_TIMEOUT, as ArduCopter's would.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

import threading
import time

from pymavlink import mavutil

from sitl_fakes import ardupilot as ap

GCS_SYSID = 255  # ArduCopter's MAV_GCS_SYSID default
MAV_COMP_ID_MISSIONPLANNER = 190
PARAM_ECHO_TIMEOUT_S = 3.0


class Pilot:
    def __init__(self, url: str, sysid: int = GCS_SYSID, target_system: int = 1, rate_hz: float = 10.0):
        self.conn = mavutil.mavlink_connection(url.replace("udpout://", "udpout:"), source_system=sysid,
                                               source_component=MAV_COMP_ID_MISSIONPLANNER)  # fmt: skip
        self.target_system = target_system
        self.period_s = 1.0 / rate_hz
        # channels 1-8: roll, pitch, throttle, yaw centred; mode switch on the SITL transmitter's FLTMODE6
        self.channels = [ap.RC_MID_PWM, ap.RC_MID_PWM, ap.RC_MID_PWM, ap.RC_MID_PWM,
                         ap.mode_switch_pwm(6), 1000, 1000, 1800]  # fmt: skip
        self.slot = 6
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._send()
        self._thread = threading.Thread(target=self._run, name="sitl-fake-pilot", daemon=True)
        self._thread.start()

    def _send(self) -> None:
        with self._lock:
            chans = list(self.channels)
            self.conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID,
                                         0, 0, 0)  # fmt: skip
            self.conn.mav.rc_channels_override_send(self.target_system, 1, *chans)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self._send()
            except OSError:
                return

    def sticks(self, throttle: int = ap.RC_MID_PWM, roll: int = ap.RC_MID_PWM, pitch: int = ap.RC_MID_PWM,
               yaw: int = ap.RC_MID_PWM) -> None:  # fmt: skip
        """Stick positions in µs (1000..2000; 1500 centred)."""
        with self._lock:
            self.channels[0:4] = [roll, pitch, throttle, yaw]
        self._send()

    def switch(self, mode: str | ap.CopterMode, timeout_s: float = PARAM_ECHO_TIMEOUT_S) -> int:
        """Flip the mode switch to ``mode``; returns the FLTMODE slot used. The fake changes mode once the new
        position has been held for its 0.2 s debounce (watch the HEARTBEAT's custom_mode)."""
        target = mode if isinstance(mode, ap.CopterMode) else ap.mode_by_name(mode)
        slot = 1 if self.slot != 1 else 2
        name = f"FLTMODE{slot}".encode()
        self.conn.mav.param_set_send(self.target_system, 1, name, float(target.value),
                                     mavutil.mavlink.MAV_PARAM_TYPE_INT8)  # fmt: skip
        end = time.monotonic() + timeout_s
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no PARAM_VALUE echo for {name.decode()} within {timeout_s} s")
            msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=min(left, 0.2))
            if msg is not None and msg.param_id == name.decode() and int(msg.param_value) == target.value:
                break
        with self._lock:
            self.channels[4] = ap.mode_switch_pwm(slot)
            self.slot = slot
        self._send()
        return slot

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self.conn.close()

    def __enter__(self) -> Pilot:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
