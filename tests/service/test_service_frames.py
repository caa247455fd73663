"""Frame codecs (JSON, binary) and vectorised validation."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from service import frames
from service.frames import FrameBatch, FrameError

NOW = 1_700_000_000.0


def make_batch(n: int = 50, t0: float = NOW - 1.0, *, f: bool = False, stat: bool = False) -> FrameBatch:
    rng = np.random.default_rng(1)
    t = t0 + np.arange(n) / 50.0
    return FrameBatch(
        t=t, V=1.0 + 0.001 * rng.standard_normal(n), theta=0.1 * rng.standard_normal(n),
        P=0.8 + 0.01 * rng.standard_normal(n), Q=0.3 + 0.01 * rng.standard_normal(n),
        f=50.0 + 0.01 * rng.standard_normal(n) if f else None,
        stat=np.zeros(n, np.uint16) if stat else None,
    )


def assert_same(a: FrameBatch, b: FrameBatch, atol: float = 0.0) -> None:
    for k in ("t", "V", "theta", "P", "Q", "f", "stat"):
        x, y = getattr(a, k), getattr(b, k)
        assert (x is None) == (y is None), k
        if x is not None:
            np.testing.assert_allclose(np.asarray(x, float), np.asarray(y, float), rtol=0, atol=atol, err_msg=k)


@pytest.mark.parametrize("f,stat", [(False, False), (True, False), (True, True), (False, True)])
def test_binary_round_trip(f, stat):
    b = make_batch(f=f, stat=stat)
    payload = frames.encode_binary(b)
    assert len(payload) == 16 + 40 * len(b) + (8 * len(b) if f else 0) + (2 * len(b) if stat else 0)
    assert_same(frames.decode(payload, frames.BINARY_ENCODING), b)


def test_binary_ns_time_round_trip():
    b = make_batch()
    out = frames.decode_binary(frames.encode_binary(b, t_ns=True))
    assert_same(out, b, atol=1e-6)


def test_json_round_trip_seconds_and_ns():
    b = make_batch(f=True, stat=True)
    assert_same(frames.decode(frames.encode_json(b), "application/json"), b)
    obj = json.loads(frames.encode_json(b))
    obj["t"] = [int(round(x * 1e9)) for x in b.t]
    out = frames.decode(json.dumps(obj).encode(), "text/json;utf-8")
    np.testing.assert_allclose(out.t, b.t, atol=1e-6)


def test_current_phasors_give_power():
    b = make_batch()
    S = b.P + 1j * b.Q
    Vc = b.V * np.exp(1j * b.theta)
    Ic = np.conj(S / Vc)  # S = V I*  =>  I = conj(S / V)
    obj = {"t": b.t.tolist(), "V": b.V.tolist(), "theta": b.theta.tolist(),
           "I": np.abs(Ic).tolist(), "phi": np.angle(Ic).tolist()}
    out = frames.decode_json(json.dumps(obj))
    np.testing.assert_allclose(out.P, b.P, atol=1e-12)
    np.testing.assert_allclose(out.Q, b.Q, atol=1e-12)
    # Same through the binary layout with the current flag.
    n = len(b)
    payload = frames.HEADER.pack(b"ASLM", 1, frames.FLAG_CURRENT, 0, n, 0) + b.t.tobytes() + np.stack(
        [b.V, b.theta, np.abs(Ic), np.angle(Ic)]).tobytes()
    out = frames.decode_binary(payload)
    np.testing.assert_allclose(out.P, b.P, atol=1e-12)
    np.testing.assert_allclose(out.Q, b.Q, atol=1e-12)


@pytest.mark.parametrize("payload,encoding,reason", [
    (b"{not json", "application/json", "malformed_json"),
    (b"[1, 2]", "application/json", "malformed_json"),
    (b'{"t": [1], "V": [1]}', "application/json", "missing_field"),
    (b'{"t": [1, 2], "V": [1], "theta": [0], "P": [1], "Q": [0]}', "application/json", "shape_mismatch"),
    (b'{"t": [1], "V": ["x"], "theta": [0], "P": [1], "Q": [0]}', "application/json", "bad_type"),
    (b'{"t": 1, "V": 1, "theta": 0, "P": 1, "Q": 0}', "application/json", "bad_type"),
    (b"ASL", frames.BINARY_ENCODING, "bad_header"),
    (struct.pack("<4sBBHII", b"XXXX", 1, 0, 0, 0, 0), frames.BINARY_ENCODING, "bad_header"),
    (struct.pack("<4sBBHII", b"ASLM", 1, 0, 0, 3, 0) + b"\0" * 10, frames.BINARY_ENCODING, "length_mismatch"),
    (b"anything", "text/plain", "unknown_encoding"),
])
def test_malformed_messages_raise_with_reason(payload, encoding, reason):
    with pytest.raises(FrameError) as info:
        frames.decode(payload, encoding)
    assert info.value.reason == reason


def test_validate_counts_each_bad_frame_once_by_reason():
    b = make_batch(20, f=True, stat=True)
    b.V = b.V.copy()
    b.P = b.P.copy()
    b.t = b.t.copy()
    b.f = b.f.copy()
    b.stat = b.stat.copy()
    b.V[0] = np.nan          # non_finite
    b.V[1] = -1.0            # out_of_range
    b.P[2] = 1e3             # out_of_range
    b.f[3] = 70.0            # out_of_range (f0 = 50)
    b.stat[4] = 0x8000       # pmu_error
    b.stat[0] = 0x8000       # also non-finite: counted once, as non_finite
    b.t[5] = NOW + 3600      # future
    v = frames.validate(b, now=NOW, max_future_s=5.0, f0=50.0)
    assert v.rejected == {"non_finite": 1, "out_of_range": 3, "pmu_error": 1, "future": 1}
    assert len(v.good) == 20 - 6
    assert np.isfinite(v.good.V).all() and (v.good.t < NOW).all()


def test_validate_all_good_is_identity():
    b = make_batch()
    v = frames.validate(b, now=NOW, max_future_s=5.0)
    assert v.rejected == {} and v.good is b
