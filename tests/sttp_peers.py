"""An STTP publisher on 127.0.0.1 for the tests: ``sttpapi``'s own ``Publisher`` with openPDC-style metadata.

The metadata is written as openPDC sends it (the package's ``MetadataTemplate.xml`` schema, a
``DeviceDetail`` per PMU, ``PhasorDetail`` rows, and ``MeasurementDetail`` rows whose signal references are
``{DEVICE}-PM{i}`` / ``{DEVICE}-PA{i}`` for phasor magnitude and angle and ``{DEVICE}-FQ`` for the
frequency), so the subscriber resolves phasor labels the way it would against a real openPDC.
"""

from __future__ import annotations

import threading
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
from c37118_peers import free_port

UNIX_TICKS = 621355968000000000  # .NET ticks (100 ns since 0001-01-01) at the Unix epoch


def ticks(t: float) -> int:
    """STTP ticks of a Unix time [s], rounded to the 100 ns the protocol carries."""
    return UNIX_TICKS + round(t * 1e7)


@dataclass
class Signal:
    """One published measurement: its point tag, signal ID and kind."""

    tag: str
    acronym: str  # VPHM, VPHA, IPHM, IPHA, FREQ, CALC, ...
    reference: str
    signal_id: uuid.UUID = field(default_factory=uuid.uuid4)
    phasor_index: int | None = None


@dataclass
class Device:
    """A PMU in the metadata: phasors (label, type V/I, source index) and, with ``freq``, a frequency."""

    acronym: str
    phasors: list[tuple[str, str]]  # (label, "V" or "I"), source indexes 1, 2, ...
    freq: bool = True
    extra: list[tuple[str, str]] = field(default_factory=list)  # (point tag, signal acronym), e.g. MW

    def signals(self) -> list[Signal]:
        out = []
        for i, (label, kind) in enumerate(self.phasors, start=1):
            out.append(Signal(f"{self.acronym}:{label}.MAG", f"{kind}PHM", f"{self.acronym}-PM{i}", phasor_index=i))
            out.append(Signal(f"{self.acronym}:{label}.ANG", f"{kind}PHA", f"{self.acronym}-PA{i}", phasor_index=i))
        if self.freq:
            out.append(Signal(f"{self.acronym}:FREQ", "FREQ", f"{self.acronym}-FQ"))
        for k, (tag, acronym) in enumerate(self.extra, start=1):
            out.append(Signal(tag, acronym, f"{self.acronym}-AV{k}"))
        return out


def metadata_xml(devices: list[Device]) -> tuple[str, dict[str, Signal]]:
    """openPDC-style metadata of ``devices`` and their signals by point tag."""
    from sttp import publisher

    template = (Path(publisher.__file__).parent / "MetadataTemplate.xml").read_text(encoding="utf-8")
    rows, signals, pid = [], {}, 0
    for dev in devices:
        rows.append(f"<DeviceDetail><UniqueID>{uuid.uuid4()}</UniqueID><IsConcentrator>false</IsConcentrator>"
                    f"<Acronym>{dev.acronym}</Acronym><Name>{dev.acronym}</Name><AccessID>0</AccessID>"
                    f"<ProtocolName>IEEE C37.118-2011</ProtocolName><FramesPerSecond>50</FramesPerSecond>"
                    f"<Enabled>true</Enabled></DeviceDetail>")
        for k, s in enumerate(dev.signals(), start=1):
            signals[s.tag] = s
            psi = "" if s.phasor_index is None else f"<PhasorSourceIndex>{s.phasor_index}</PhasorSourceIndex>"
            rows.append(f"<MeasurementDetail><DeviceAcronym>{dev.acronym}</DeviceAcronym>"
                        f"<ID>PPA:{len(signals)}</ID><SignalID>{s.signal_id}</SignalID>"
                        f"<PointTag>{escape(s.tag)}</PointTag><SignalReference>{s.reference}</SignalReference>"
                        f"<SignalAcronym>{s.acronym}</SignalAcronym>{psi}<Description>{k}</Description>"
                        f"<Internal>true</Internal><Enabled>true</Enabled></MeasurementDetail>")
        for i, (label, kind) in enumerate(dev.phasors, start=1):
            pid += 1
            rows.append(f"<PhasorDetail><ID>{pid}</ID><DeviceAcronym>{dev.acronym}</DeviceAcronym>"
                        f"<Label>{escape(label)}</Label><Type>{kind}</Type><Phase>+</Phase>"
                        f"<DestinationPhasorID>0</DestinationPhasorID><SourceIndex>{i}</SourceIndex></PhasorDetail>")
    head, tail = template.split("<SchemaVersion>", 1)
    return head + "\n".join(rows) + "\n<SchemaVersion>" + tail, signals


class SttpPeer:
    """``sttpapi``'s Publisher listening on a free port with the metadata of ``devices``.

    ``publish(t, values)`` sends one measurement per point tag in ``values`` at Unix time ``t``
    (``flags`` per tag optional); ``stop()`` drops every subscriber and stops listening; ``start()`` again
    listens on the same port.
    """

    def __init__(self, devices: list[Device], port: int | None = None) -> None:
        from sttp.data.dataset import DataSet

        self.xml, self.signals = metadata_xml(devices)
        self.dataset, err = DataSet.from_xml(self.xml)
        assert err is None, err
        self.port = port or free_port()
        self.connected = threading.Event()
        self.publisher = None
        self.start()

    def start(self) -> SttpPeer:
        from sttp.publisher import Publisher

        pub = Publisher()
        pub.statusmessage_logger = None
        pub.errormessage_logger = None
        pub.clientconnected_receiver = lambda _c: self.connected.set()
        pub.clientdisconnected_receiver = lambda _c: self.connected.clear()
        pub.start(self.port)
        pub.define_metadata(self.dataset)
        self.publisher = pub
        return self

    def subscribers(self) -> int:
        return len(self.publisher.subscriber_connections) if self.publisher is not None else 0

    def publish(self, t: float, values: dict[str, float], flags: dict[str, int] | None = None) -> None:
        from sttp.transport.constants import StateFlags
        from sttp.transport.measurement import Measurement

        # int64, not the uint64 of sttp.ticks: sttpapi 0.7.6's TSSC encoder adds its int64 time deltas to the
        # previous timestamp, which numpy does in float64 for a uint64 (exact only to 128 ticks), so it sends
        # "same delta as before" for timestamps a few ticks off and the subscriber's times drift, then break.
        ts = np.int64(ticks(t))
        flags = flags or {}
        self.publisher.publish_measurements([
            Measurement(self.signals[tag].signal_id, np.float64(v), ts, StateFlags(flags.get(tag, 0)))
            for tag, v in values.items()])

    def stop(self) -> None:
        if self.publisher is not None:
            self.publisher.dispose()
            self.publisher = None
