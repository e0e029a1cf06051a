"""MAVLink 2 over one UDP socket: answers every peer it hears from, plus fixed ``--peer`` addresses.

The port is bound *exclusively*: no SO_REUSEADDR, so a second fake (or a MAVSDK ``udpin`` listener,
which binds with SO_REUSEADDR) on the same port fails to bind instead of silently stealing packets.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

import socket

from pymavlink.dialects.v20 import common as mavlink

SYSTEM_ID = 1
COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1
MAX_DATAGRAM = 65535


class PortInUse(OSError):
    pass


class Link:
    def __init__(self, port: int, bind_host: str = "0.0.0.0", static_peers: list[tuple[str, int]] | None = None,
                 sysid: int = SYSTEM_ID):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((bind_host, port))
        except OSError as exc:
            self.sock.close()
            raise PortInUse(f"cannot bind UDP port {port}: {exc.strerror}") from None
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.sysid = sysid
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=COMPONENT_ID)
        self.peers: dict[tuple[str, int], mavlink.MAVLink] = {}
        self.static_peers = [(socket.gethostbyname(h), p) for h, p in (static_peers or [])]
        self.bytes_out = 0
        self.packets_in = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def receive(self):
        """All messages waiting on the socket, as (message, peer address) pairs. Never blocks."""
        out = []
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:  # ICMP from a peer that went away
                continue
            parser = self.peers.get(addr)
            if parser is None:
                parser = mavlink.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT_ID)
                parser.robust_parsing = True
                self.peers[addr] = parser
            try:
                msgs = parser.parse_buffer(data) or []
            except mavlink.MAVError:
                continue
            for m in msgs:
                if m.get_type() != "BAD_DATA":
                    self.packets_in += 1
                    out.append((m, addr))

    def send(self, msg) -> None:
        buf = msg.pack(self.mav)
        for addr in list(self.peers) + self.static_peers:
            try:
                self.sock.sendto(buf, addr)
                self.bytes_out += len(buf)
            except (BlockingIOError, ConnectionRefusedError, InterruptedError):
                pass
            except OSError:
                pass

    def close(self) -> None:
        self.sock.close()
