"""TCP and UDP payloads out of a packet capture (classic pcap, Ethernet or raw IPv4), for C37.118 captures.

PMU data is often shared as a capture of the PMU-PDC conversation.  :func:`streams` returns each TCP
direction's payload in sequence order (retransmitted segments once) and each UDP flow's datagrams, so
the C37.118 stream decoder can read them as it reads a socket.  pcapng and IPv6 are not read.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

MAGIC = {b"\xd4\xc3\xb2\xa1": "<", b"\xa1\xb2\xc3\xd4": ">", b"\x4d\x3c\xb2\xa1": "<", b"\xa1\xb2\x3c\x4d": ">"}
LINK_ETHERNET, LINK_RAW = 1, 101


class PcapError(ValueError):
    """A file that is not a classic pcap capture of IPv4 traffic."""


@dataclass
class Flow:
    """One direction of a TCP connection, or one UDP flow: (src, sport, dst, dport)."""

    key: tuple[str, int, str, int]
    proto: str
    segments: dict[int, bytes] = field(default_factory=dict)  # TCP: sequence number → payload
    datagrams: list[bytes] = field(default_factory=list)  # UDP, in capture order

    def payload(self) -> bytes:
        """The TCP byte stream in sequence order (overlaps taken once), or the UDP datagrams joined."""
        if self.proto == "udp":
            return b"".join(self.datagrams)
        out, end = bytearray(), None
        for seq in sorted(self.segments):
            data = self.segments[seq]
            if end is not None and seq < end:
                data = data[end - seq:]
            out += data
            end = max(end or seq, seq + len(self.segments[seq]))
        return bytes(out)


def _ip(b: bytes) -> str:
    return ".".join(str(x) for x in b)


def streams(path: str | Path) -> dict[tuple[str, int, str, int], Flow]:
    """Flows of a capture by (src, sport, dst, dport).

    Raises
    ------
    PcapError
        Not a classic pcap file, or a link type other than Ethernet and raw IP.
    """
    raw = Path(path).read_bytes()
    endian = MAGIC.get(raw[:4])
    if endian is None:
        raise PcapError(f"{path}: not a classic pcap file (pcapng is not read)")
    link = struct.unpack_from(endian + "I", raw, 20)[0]
    if link not in (LINK_ETHERNET, LINK_RAW):
        raise PcapError(f"{path}: link type {link}; Ethernet (1) and raw IP (101) are read")
    flows: dict[tuple, Flow] = {}
    pos = 24
    while pos + 16 <= len(raw):
        incl = struct.unpack_from(endian + "I", raw, pos + 8)[0]
        pkt = raw[pos + 16: pos + 16 + incl]
        pos += 16 + incl
        if link == LINK_ETHERNET:
            if len(pkt) < 14:
                continue
            etype, off = struct.unpack_from(">H", pkt, 12)[0], 14
            if etype == 0x8100:  # VLAN tag
                etype, off = struct.unpack_from(">H", pkt, 16)[0], 18
            if etype != 0x0800:
                continue
            pkt = pkt[off:]
        if len(pkt) < 20 or pkt[0] >> 4 != 4:
            continue
        ihl, total, proto = (pkt[0] & 0x0F) * 4, struct.unpack_from(">H", pkt, 2)[0], pkt[9]
        src, dst, seg = _ip(pkt[12:16]), _ip(pkt[16:20]), pkt[ihl:total]
        if proto == 6 and len(seg) >= 20:
            sport, dport, seq = struct.unpack_from(">HHI", seg, 0)
            data = seg[(seg[12] >> 4) * 4:]
            if data:
                flow = flows.setdefault((src, sport, dst, dport), Flow((src, sport, dst, dport), "tcp"))
                flow.segments.setdefault(seq, data)
        elif proto == 17 and len(seg) >= 8:
            sport, dport = struct.unpack_from(">HH", seg, 0)
            flow = flows.setdefault((src, sport, dst, dport), Flow((src, sport, dst, dport), "udp"))
            flow.datagrams.append(seg[8:])
    return flows


def pmu_payload(path: str | Path, port: int = 4712) -> bytes:
    """What the PMU sent in a capture: the payload of the flows from ``port`` (TCP or UDP), joined.

    Raises
    ------
    PcapError
        No flow from that port.
    """
    flows = [f for k, f in streams(path).items() if k[1] == port]
    if not flows:
        raise PcapError(f"{path}: nothing sent from port {port}")
    return b"".join(f.payload() for f in flows)
