"""Which phasors form each load bus: the TOML mapping shared by the C37.118 bridge, the capture readers and
COMTRADE.

A load bus is its voltage phasor and the current phasor(s) of the feeder(s) into the load.  Per frame::

    V₁ = (V_a + a·V_b + a²·V_c) / 3      (a = e^{j2π/3}; a single named phasor is taken as V₁ itself)
    S  = P + jQ = 3 · V₁ · conj(Σ ± I₁)  (three-phase power from line-to-neutral RMS phasors)
    V [pu] = |V₁| / (base_kv·1e3/√3),  θ = arg V₁,  P, Q [pu] = S / (base_mva·1e6)

Example (``pdc.toml``)::

    [c37118]                 # the stream (only the C37.118 bridge reads this table)
    host = "10.0.0.5"
    port = 4712
    idcode = 7734            # IDCODE of the PDC/PMU data stream
    transport = "tcp"        # or "udp": commands over TCP, data on udp_port
    udp_port = 4713

    [buses.feeder_7]
    pmu = "Station A"        # station name or IDCODE of the PMU block in the stream
    voltage = "V1LPM"        # or ["VA", "VB", "VC"]: the positive sequence is formed
    current = ["I1", "-I2"]  # feeders summed; "-" reverses one measured away from the load;
                             # a nested ["IA", "IB", "IC"] is one feeder's three phases
    base_kv = 230.0          # line-to-line [kV]
    base_mva = 100.0         # three-phase [MVA] (default: the top-level base_mva, else 100)

    [buses.feeder_9]         # STTP only: a publisher that has the load's power itself
    pmu = "FEEDER9"
    voltage = "V1"
    power = ["FEEDER9:MW", "FEEDER9:MVAR"]   # three-phase P [MW] and Q [Mvar], instead of current
    base_kv = 69.0
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from service.frames import FrameBatch

if sys.version_info >= (3, 11):
    import tomllib
else:  # pydantic-settings' TOML source brings tomli on 3.10
    import tomli as tomllib

A = np.exp(2j * np.pi / 3)


class MappingError(ValueError):
    """A mapping file that does not say what it must, or names phasors the source does not have."""


@dataclass(frozen=True)
class Feeder:
    """One feeder's current: one positive-sequence phasor or three phase phasors, and its direction."""

    phasors: tuple[str, ...]
    sign: float = 1.0


@dataclass(frozen=True)
class BusMap:
    """How one load bus is formed from a PMU's phasors."""

    bus: str
    pmu: int | str
    voltage: tuple[str, ...]
    feeders: tuple[Feeder, ...]
    base_kv: float
    base_mva: float
    power: tuple[str, str] | None = None  # P [MW] and Q [Mvar] measurements instead of feeders (STTP)

    @property
    def v_base(self) -> float:
        """Line-to-neutral voltage base [V]."""
        return self.base_kv * 1e3 / math.sqrt(3.0)

    @property
    def s_base(self) -> float:
        """Three-phase power base [VA]."""
        return self.base_mva * 1e6


@dataclass(frozen=True)
class Mapping:
    """The buses of a mapping file and its protocol tables (e.g. ``c37118``) as given."""

    buses: tuple[BusMap, ...]
    tables: dict[str, Any]


def _names(value: Any, where: str) -> tuple[str, ...]:
    if isinstance(value, str):
        return (value,)
    if isinstance(value, list) and len(value) == 3 and all(isinstance(v, str) for v in value):
        return tuple(value)
    raise MappingError(f"{where}: a phasor name or a list of three (phases A, B, C), got {value!r}")


def _feeder(value: Any, where: str) -> Feeder:
    names = _names(value, where)
    sign = 1.0
    if all(n.startswith("-") for n in names):
        names, sign = tuple(n[1:] for n in names), -1.0
    return Feeder(names, sign)


def parse_mapping(obj: dict[str, Any], source: str = "mapping", *, power: bool = False) -> Mapping:
    """Check a parsed mapping (see the module docstring) and return its buses.

    Parameters
    ----------
    obj : dict
        The parsed TOML.
    source : str
        Named in error messages (the file).
    power : bool
        Whether a bus may give ``power = [P, Q]`` instead of ``current`` (sources that carry P and Q as
        measurements of their own, i.e. STTP; the phasor-only readers leave it False and so refuse it).

    Raises
    ------
    MappingError
        Naming the bus and key at fault.
    """
    buses = obj.get("buses")
    if not isinstance(buses, dict) or not buses:
        raise MappingError(f"{source}: no [buses.NAME] tables")
    default_mva = float(obj.get("base_mva", 100.0))
    out = []
    for bus, spec in buses.items():
        where = f"{source}: buses.{bus}"
        if not isinstance(spec, dict):
            raise MappingError(f"{where}: must be a table")
        if "power" in spec and not power:
            raise MappingError(f"{where}: power = [P, Q] is read by the STTP source only; this one needs current")
        flow = "power" if "power" in spec else "current"
        missing = [k for k in ("pmu", "voltage", flow, "base_kv") if k not in spec]
        if missing:
            raise MappingError(f"{where}: missing {', '.join(missing)}")
        unknown = set(spec) - {"pmu", "voltage", flow, "base_kv", "base_mva"}
        if unknown:
            raise MappingError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
        feeders, pq = (), None
        if flow == "power":
            pq = spec["power"]
            if not (isinstance(pq, list) and len(pq) == 2 and all(isinstance(n, str) for n in pq)):
                raise MappingError(f"{where}.power: [P, Q] measurement names (MW, Mvar), got {pq!r}")
            pq = tuple(pq)
        else:
            cur = spec["current"]
            currents = [cur] if isinstance(cur, str) else cur
            if not isinstance(currents, list) or not currents:
                raise MappingError(f"{where}.current: a name or a list of feeders, got {cur!r}")
            feeders = tuple(_feeder(c, f"{where}.current") for c in currents)
        base_kv, base_mva = float(spec["base_kv"]), float(spec.get("base_mva", default_mva))
        if base_kv <= 0 or base_mva <= 0:
            raise MappingError(f"{where}: base_kv and base_mva must be > 0")
        out.append(BusMap(str(bus), spec["pmu"], _names(spec["voltage"], f"{where}.voltage"), feeders,
                          base_kv, base_mva, pq))
    return Mapping(tuple(out), {k: v for k, v in obj.items() if isinstance(v, dict) and k != "buses"})


def load_mapping(path: str | Path, *, power: bool = False) -> Mapping:
    """Read and check a mapping TOML file (``power``: see :func:`parse_mapping`)."""
    path = Path(path)
    try:
        obj = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise MappingError(f"{path}: {exc}") from None
    return parse_mapping(obj, str(path), power=power)


def positive_sequence(phases: np.ndarray) -> np.ndarray:
    """Positive sequence of phase phasors, columns A, B, C: (A + a·B + a²·C) / 3."""
    return (phases[:, 0] + A * phases[:, 1] + A * A * phases[:, 2]) / 3.0


def bus_batch(bm: BusMap, t: np.ndarray, voltage: np.ndarray, currents: list[np.ndarray],
              f: np.ndarray | None, stat: np.ndarray | None) -> FrameBatch:
    """Frames of one bus from its phasors in volts and amperes.

    Parameters
    ----------
    bm : BusMap
    t : ndarray
        Frame times, UTC since the epoch [s].
    voltage : ndarray of complex, (n,) or (n, 3)
        Line-to-neutral voltage phasor(s) [V RMS], positive sequence or phases A, B, C.
    currents : list of ndarray of complex, (n,) or (n, 3)
        One per feeder, in ``bm.feeders`` order [A RMS].
    f : ndarray or None
        Frequency [Hz].
    stat : ndarray of uint16 or None
        C37.118 STAT words (data-error bits reject frames in validation).
    """
    v1 = _v1(voltage)
    i1 = np.zeros_like(v1)
    for fd, cur in zip(bm.feeders, currents, strict=True):
        i1 = i1 + fd.sign * (positive_sequence(cur) if cur.ndim == 2 else cur)
    s = 3.0 * v1 * np.conj(i1) / bm.s_base
    return FrameBatch(t=np.asarray(t, np.float64), V=np.abs(v1) / bm.v_base, theta=np.angle(v1),
                      P=s.real.copy(), Q=s.imag.copy(), f=None if f is None else np.asarray(f, np.float64),
                      stat=stat)


def _v1(voltage: np.ndarray) -> np.ndarray:
    return positive_sequence(voltage) if voltage.ndim == 2 else voltage


def power_batch(bm: BusMap, t: np.ndarray, voltage: np.ndarray, p_mw: np.ndarray, q_mvar: np.ndarray,
                f: np.ndarray | None, stat: np.ndarray | None) -> FrameBatch:
    """Frames of a bus whose publisher measures its power (``bm.power``): V, θ from the voltage phasor(s).

    ``p_mw`` and ``q_mvar`` are the three-phase active [MW] and reactive [Mvar] power into the load; the
    other parameters are those of :func:`bus_batch`.
    """
    v1 = _v1(voltage)
    return FrameBatch(t=np.asarray(t, np.float64), V=np.abs(v1) / bm.v_base, theta=np.angle(v1),
                      P=np.asarray(p_mw, np.float64) * 1e6 / bm.s_base,
                      Q=np.asarray(q_mvar, np.float64) * 1e6 / bm.s_base,
                      f=None if f is None else np.asarray(f, np.float64), stat=stat)
