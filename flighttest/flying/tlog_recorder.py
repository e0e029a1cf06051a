"""A ``.tlog`` recorder: a pymavlink parser on a local UDP port, writing what MAVSDK forwards to it.

MAVSDK forwards the vehicle's traffic to a ``udpout://127.0.0.1:PORT`` connection added with
``ForwardingOption.ON`` (CONVENTIONS §4). The recorder binds that port first (port 0 → the OS picks a
free one), parses the datagrams with pymavlink so only whole, CRC-checked frames are written, and
stores each as the 8-byte big-endian microsecond timestamp + raw frame that MAVProxy, MAVExplorer
and ``mavutil.mavlink_connection(path)`` read. It runs in a daemon thread and flushes the file at
least every half second, so a killed process leaves a readable log.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

FLUSH_EVERY_S = 0.5


class TlogRecorder:
    def __init__(self, path: Path | str, host: str = "127.0.0.1") -> None:
        self.path = Path(path)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, 0))
        self._sock.settimeout(0.2)
        self.host = host
        self.port = self._sock.getsockname()[1]
        self._file = open(self.path, "wb")  # noqa: SIM115 (lives as long as the recorder)
        self._mav = mavlink2.MAVLink(None)
        self._mav.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tlog-recorder", daemon=True)
        self.messages = 0
        self.bad_data = 0
        self.write_errors = 0

    @property
    def forward_url(self) -> str:
        """The MAVSDK connection URL that feeds this recorder."""
        return f"udpout://{self.host}:{self.port}"

    def start(self) -> TlogRecorder:
        self._thread.start()
        return self

    def _run(self) -> None:
        last_flush = time.monotonic()
        while not self._stop.is_set():
            try:
                data = self._sock.recv(65535)
            except TimeoutError:
                data = b""
            except OSError:
                break
            if data:
                try:
                    msgs = self._mav.parse_buffer(data) or []
                except Exception:  # a corrupt datagram must never stop the recording
                    msgs = []
                    self.bad_data += 1
                usec = int(time.time() * 1e6)
                for m in msgs:
                    if m.get_type() == "BAD_DATA":
                        self.bad_data += 1
                        continue
                    self._write(struct.pack(">Q", usec) + m.get_msgbuf())
                    self.messages += 1
            now = time.monotonic()
            if now - last_flush >= FLUSH_EVERY_S:
                self._write(None)
                last_flush = now
        self._write(None)

    def _write(self, record: bytes | None) -> None:
        """A record (None: a flush); a full disk is counted and recording goes on (it may free up)."""
        try:
            if record is None:
                self._file.flush()
            else:
                self._file.write(record)
        except OSError:
            self.write_errors += 1

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        try:
            self._sock.close()
        finally:
            if not self._file.closed:
                try:
                    self._file.close()
                except OSError:
                    self.write_errors += 1
