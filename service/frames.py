"""PMU frame batches on the wire: JSON and a compact binary encoding, decoded and validated vectorised.

One Zenoh message on ``{prefix}/pmu/{bus}`` carries a batch of frames of one bus.  The Zenoh sample
encoding says which codec applies:

``application/json`` (or ``text/json``)
    ``{"t": [...], "V": [...], "theta": [...], "P": [...], "Q": [...]}`` with optional ``"f"`` [Hz] and
    ``"stat"`` (IEEE C37.118 STAT word per frame).  ``t`` is UTC since the epoch in seconds (floats) or
    nanoseconds (integers; any ``|t| > 1e14`` is taken as ns).  Instead of ``P``/``Q`` a PMU may send the
    current phasor ``"I"`` (magnitude [pu]) and ``"phi"`` (angle [rad], same reference as ``theta``):
    P + jQ = V·I* gives P = V·I·cos(θ − φ), Q = V·I·sin(θ − φ).

``application/x-aslm-pmu`` (:data:`BINARY_ENCODING`)
    A 16-byte little-endian header then column-major arrays (see :func:`encode_binary`).

Validation flags frames (not whole batches): non-finite values, times at or before the epoch, V outside
(0, 3] pu, |P|, |Q| > 100 pu, f outside f0 ± 10 Hz, STAT data-error bits (15–14) set.  A message that
cannot be decoded at all is rejected whole with a reason, and the frames it is counted as holding are
never more than its bytes can hold (a header's claim is not believed).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field

import numpy as np

from aslm_core.window import REQUIRED

JSON_ENCODINGS = frozenset({"application/json", "text/json"})
BINARY_ENCODING = "application/x-aslm-pmu"

MAGIC = b"ASLM"
VERSION = 1
HEADER = struct.Struct("<4sBBHII")  # magic, version, flags, reserved, n frames, reserved
FLAG_F = 0x01  # a frequency column follows Q
FLAG_STAT = 0x02  # a uint16 STAT column ends the message
FLAG_T_NS = 0x04  # t is int64 ns since the epoch (else float64 s)
FLAG_CURRENT = 0x08  # columns 4-5 are I [pu] and phi [rad] instead of P, Q

NS_THRESHOLD = 1e14  # |t| above this is nanoseconds (1e14 s is 3 million years)
V_MAX = 3.0
PQ_MAX = 100.0
F_TOL = 10.0
STAT_DATA_ERROR = 0xC000  # C37.118 STAT bits 15-14: data error

COLUMNS = REQUIRED  # the columns every batch has, in the binary layout's order (f and stat optional)


class FrameError(ValueError):
    """A message that cannot be decoded; ``reason`` is the metric label, ``n`` frames it held if known.

    ``n`` never exceeds what the message's bytes could hold, so a forged count cannot poison counters.
    """

    def __init__(self, reason: str, message: str, n: int = 0) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason
        self.n = n


@dataclass
class FrameBatch:
    """Frames of one bus, column arrays of equal length.

    Attributes
    ----------
    t : ndarray of float64
        Frame times, UTC since the epoch [s].
    V, theta, P, Q : ndarray of float64
        Voltage magnitude [pu], angle [rad], active and reactive power [pu].
    f : ndarray of float64 or None
        Bus frequency [Hz].
    stat : ndarray of uint16 or None
        PMU STAT words.
    """

    t: np.ndarray
    V: np.ndarray
    theta: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    f: np.ndarray | None = None
    stat: np.ndarray | None = None
    cols: np.ndarray | None = field(default=None, repr=False)  # rows t, V, theta, P, Q[, f] if built

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def block(self) -> np.ndarray:
        """Rows t, V, theta, P, Q (and f) as one float64 array; a view of the payload when decoded.

        Why: whole-batch checks and copies then cost one numpy call instead of one per column.
        """
        if self.cols is None:
            rows = [getattr(self, c) for c in COLUMNS] + ([self.f] if self.f is not None else [])
            self.cols = np.stack(rows).astype(np.float64, copy=False)
        return self.cols


@dataclass
class Validated:
    """Result of :func:`validate`: the good frames and the count of rejected ones per reason."""

    good: FrameBatch
    rejected: dict[str, int]


def _as_seconds(t: np.ndarray) -> np.ndarray:
    if t.size and np.fmax.reduce(np.abs(t)) > NS_THRESHOLD:  # NaN-ignoring like nanmax, silent when all NaN
        return t * 1e-9
    return t


def decode_json(payload: bytes | str) -> FrameBatch:
    """Decode a JSON frame batch.

    Raises
    ------
    FrameError
        ``malformed_json``, ``missing_field``, ``shape_mismatch`` or ``bad_type``.
    """
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:  # RecursionError: [[[[...]]]]
        raise FrameError("malformed_json", str(exc)[:200]) from None
    if not isinstance(obj, dict):
        raise FrameError("malformed_json", "top level must be an object")
    n = len(obj["t"]) if isinstance(obj.get("t"), list) else 0
    current = "P" not in obj and "I" in obj
    needed = ("t", "V", "theta", "I", "phi") if current else COLUMNS
    missing = [k for k in needed if obj.get(k) is None]  # null counts as missing (only f, stat are optional)
    if missing:
        raise FrameError("missing_field", f"missing {', '.join(missing)}", n)
    cols: dict[str, np.ndarray] = {}
    for key in (*needed, "f", "stat"):
        if key not in obj or obj[key] is None:
            continue
        val = obj[key]
        if not isinstance(val, list):
            raise FrameError("bad_type", f"{key} must be an array", n)
        try:
            # None (JSON null) becomes nan and is rejected per frame by validate().
            arr = _column(val, ns=key == "t" and _all_int(val))
        except (TypeError, ValueError, OverflowError):
            raise FrameError("bad_type", f"{key} must hold numbers", n) from None
        if arr.ndim != 1:
            raise FrameError("bad_type", f"{key} must be a flat array", n)
        cols[key] = arr
    lengths = {k: a.shape[0] for k, a in cols.items()}
    if len(set(lengths.values())) != 1:
        raise FrameError("shape_mismatch", f"column lengths differ: {lengths}", n)
    t = _as_seconds(cols["t"].astype(np.float64))
    stat = cols.get("stat")
    if stat is not None:
        with np.errstate(invalid="ignore"):
            bad = ~((stat >= 0) & (stat <= 0xFFFF) & (stat == np.floor(stat)) | ~np.isfinite(stat))
        if bad.any():  # a STAT word is 16 bits: 70000 must not wrap into a plausible one
            raise FrameError("bad_type", "stat must hold integers 0..65535", n)
        stat = np.where(np.isfinite(stat), stat, 0xFFFF).astype(np.uint16)
    P, Q = (power_from_current(cols["V"], cols["theta"], cols["I"], cols["phi"]) if current
            else (cols["P"], cols["Q"]))
    return FrameBatch(t=t, V=cols["V"], theta=cols["theta"], P=P, Q=Q, f=cols.get("f"), stat=stat)


def _all_int(values: list) -> bool:
    return all(type(v) is int for v in values)


def _column(values: list, *, ns: bool) -> np.ndarray:
    """One JSON column as an array: int64 for integer times (ns), float64 otherwise.

    An integer beyond int64 is no time any PMU sends; as float64 it becomes a far-future (or
    pre-epoch) time that validate() rejects per frame, so the message is counted like any other.
    """
    if ns:
        try:
            return np.array(values, dtype=np.int64)
        except OverflowError:
            pass
    return np.array(values, dtype=np.float64)


def power_from_current(V: np.ndarray, theta: np.ndarray, I: np.ndarray, phi: np.ndarray):  # noqa: E741
    """Complex power of the load from voltage and current phasors: P + jQ = V·I*.

    Parameters
    ----------
    V, theta : ndarray
        Voltage magnitude [pu] and angle [rad].
    I, phi : ndarray
        Current magnitude [pu] and angle [rad] (current drawn by the load).

    Returns
    -------
    P, Q : ndarray
        Active and reactive power [pu].
    """
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite inputs give non-finite P, Q: rejected later
        s = V * I
        delta = theta - phi
        return s * np.cos(delta), s * np.sin(delta)


def encode_json(batch: FrameBatch) -> bytes:
    """Encode a batch as the JSON frame payload (t in seconds)."""
    obj = {k: getattr(batch, k).tolist() for k in COLUMNS}
    if batch.f is not None:
        obj["f"] = batch.f.tolist()
    if batch.stat is not None:
        obj["stat"] = batch.stat.astype(int).tolist()
    return json.dumps(obj, separators=(",", ":")).encode()


def encode_binary(batch: FrameBatch, *, t_ns: bool = False) -> bytes:
    """Encode a batch in the compact binary layout.

    Layout (little-endian)::

        offset  size  field
        0       4     magic b"ASLM"
        4       1     version (1)
        5       1     flags: 0x01 f column, 0x02 stat column, 0x04 t as int64 ns, 0x08 I/phi not P/Q
        6       2     reserved (0)
        8       4     n, frames in the batch (uint32)
        12      4     reserved (0)
        16      8n    t: float64 s since the epoch (or int64 ns with flag 0x04)
        ...     8n    V [pu], then theta [rad], then P [pu] (or I), then Q [pu] (or phi): float64 each
        ...     8n    f [Hz] float64, if flag 0x01
        ...     2n    stat uint16, if flag 0x02

    Total size 16 + 40n (+ 8n with f) (+ 2n with stat) bytes.
    """
    n = len(batch)
    flags = (FLAG_F if batch.f is not None else 0) | (FLAG_STAT if batch.stat is not None else 0)
    flags |= FLAG_T_NS if t_ns else 0
    t = np.round(batch.t * 1e9).astype("<i8") if t_ns else batch.t.astype("<f8")
    cols = [np.stack([batch.V, batch.theta, batch.P, batch.Q]).astype("<f8")]
    if batch.f is not None:
        cols.append(np.asarray(batch.f, dtype="<f8")[None, :])
    parts = [HEADER.pack(MAGIC, VERSION, flags, 0, n, 0), t.tobytes(), *(c.tobytes() for c in cols)]
    if batch.stat is not None:
        parts.append(np.asarray(batch.stat, dtype="<u2").tobytes())
    return b"".join(parts)


def decode_binary(payload: bytes) -> FrameBatch:
    """Decode the binary layout of :func:`encode_binary` without per-frame Python work.

    Raises
    ------
    FrameError
        ``bad_header`` (short, wrong magic or version) or ``length_mismatch``.
    """
    if len(payload) < HEADER.size:
        raise FrameError("bad_header", f"{len(payload)} bytes, header needs {HEADER.size}")
    magic, version, flags, _, n, _ = HEADER.unpack_from(payload, 0)
    if magic != MAGIC or version != VERSION:
        raise FrameError("bad_header", f"magic {magic!r} version {version}")
    ncols = 5 + (1 if flags & FLAG_F else 0)
    per_frame = 8 * ncols + (2 if flags & FLAG_STAT else 0)
    expected = HEADER.size + per_frame * n
    if len(payload) != expected:
        # Count the frames the bytes could hold, not the header's claim (n = 0xFFFFFFFF in 16 bytes).
        held = min(n, (len(payload) - HEADER.size) // per_frame)
        raise FrameError("length_mismatch", f"{len(payload)} bytes, header says {expected} for n={n}", held)
    if not flags & (FLAG_T_NS | FLAG_CURRENT):
        # Common case: the columns after the header are one (ncols, n) float64 block, viewed in place.
        block = np.frombuffer(payload, dtype="<f8", count=n * ncols, offset=HEADER.size).reshape(ncols, n)
        stat = None
        if flags & FLAG_STAT:
            stat = np.frombuffer(payload, dtype="<u2", count=n, offset=HEADER.size + 8 * n * ncols)
        return FrameBatch(t=block[0], V=block[1], theta=block[2], P=block[3], Q=block[4],
                          f=block[5] if flags & FLAG_F else None, stat=stat, cols=block)
    if flags & FLAG_T_NS:
        t = np.frombuffer(payload, dtype="<i8", count=n, offset=HEADER.size) * 1e-9
    else:
        t = np.frombuffer(payload, dtype="<f8", count=n, offset=HEADER.size)
    body = np.frombuffer(payload, dtype="<f8", count=n * (ncols - 1), offset=HEADER.size + 8 * n)
    body = body.reshape(ncols - 1, n)
    stat = None
    if flags & FLAG_STAT:
        stat = np.frombuffer(payload, dtype="<u2", count=n, offset=HEADER.size + 8 * n * ncols)
    V, theta = body[0], body[1]
    if flags & FLAG_CURRENT:
        P, Q = power_from_current(V, theta, body[2], body[3])
    else:
        P, Q = body[2], body[3]
    return FrameBatch(t=t, V=V, theta=theta, P=P, Q=Q, f=body[4] if flags & FLAG_F else None, stat=stat)


def decode(payload: bytes, encoding: str) -> FrameBatch:
    """Decode by Zenoh encoding string; ``unknown_encoding`` for anything else.

    A schema suffix (``application/json;utf-8``) is ignored.
    """
    base = encoding.split(";", 1)[0].strip().lower()
    if base in JSON_ENCODINGS:
        return decode_json(payload)
    if base == BINARY_ENCODING:
        return decode_binary(payload)
    raise FrameError("unknown_encoding", f"encoding {encoding!r}; use application/json or {BINARY_ENCODING}")


def validate(batch: FrameBatch, *, now: float, max_future_s: float, f0: float = 50.0) -> Validated:
    """Flag bad frames vectorised; return the good ones and rejected counts by reason.

    Each rejected frame is counted once, under the first reason that applies in the order
    ``non_finite``, ``bad_time`` (at or before the epoch: no PMU clock reads that), ``pmu_error``,
    ``out_of_range``, ``future``.

    Parameters
    ----------
    batch : FrameBatch
    now : float
        Current UTC time [s].
    max_future_s : float
        Frames later than ``now + max_future_s`` are rejected as ``future`` [s].
    f0 : float
        Nominal frequency [Hz], for the frequency range check.
    """
    n = len(batch)
    if n == 0:
        return Validated(batch, {})
    # Fast path: per-row min and max (two numpy calls) decide for the whole batch; NaN propagates
    # through min/max and fails every comparison, so any doubt falls through to the per-frame pass.
    cols = batch.block()
    lo, hi = cols.min(axis=1).tolist(), cols.max(axis=1).tolist()
    ok = (lo[0] > 0.0 and hi[0] <= now + max_future_s and lo[1] > 0 and hi[1] <= V_MAX
          and lo[2] > -math.inf and hi[2] < math.inf and lo[3] >= -PQ_MAX and hi[3] <= PQ_MAX
          and lo[4] >= -PQ_MAX and hi[4] <= PQ_MAX
          and (batch.f is None or (lo[5] >= f0 - F_TOL and hi[5] <= f0 + F_TOL)))
    if ok and (batch.stat is None or not (batch.stat & STAT_DATA_ERROR).any()):
        return Validated(batch, {})
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(cols).all(axis=0)
        in_range = (batch.V > 0) & (batch.V <= V_MAX) & (np.abs(batch.P) <= PQ_MAX) & (np.abs(batch.Q) <= PQ_MAX)
        if batch.f is not None:
            in_range &= np.abs(batch.f - f0) <= F_TOL
        future = batch.t > now + max_future_s
        bad_time = batch.t <= 0.0
    bad_pmu = (batch.stat & STAT_DATA_ERROR) != 0 if batch.stat is not None else None
    if bad_pmu is None:
        bad_pmu = np.zeros(n, bool)
    rejected: dict[str, int] = {}
    remaining = np.ones(n, bool)
    for reason, bad in (("non_finite", ~finite), ("bad_time", bad_time), ("pmu_error", bad_pmu),
                        ("out_of_range", ~in_range), ("future", future)):
        hit = bad & remaining
        k = int(hit.sum())
        if k:
            rejected[reason] = k
            remaining &= ~hit
    good = FrameBatch(
        **{c: getattr(batch, c)[remaining] for c in COLUMNS}, f=None if batch.f is None else batch.f[remaining],
        stat=None if batch.stat is None else batch.stat[remaining],
    )
    return Validated(good, rejected)
