"""Property-based fuzzing (hypothesis) of the frame decoders, the ingest accounting and the REST inputs.

Properties: a decoder either returns a batch of equal-length columns or raises ``FrameError`` whose frame
count is no more than the message's bytes can hold; the Inlet never raises and counts every frame it
was given exactly once (buffered or rejected with a reason); REST answers hostile paths, query strings
and bodies with 4xx, never 5xx.  ``benchmarks/fuzz_ingest.py`` runs the same kind of input at volume.
"""

from __future__ import annotations

import json
import struct
import warnings
from urllib.parse import quote

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from service_helpers import settings_for

from service.api import create_app
from service.buffers import BufferStore
from service.clock import ManualClock
from service.frames import BINARY_ENCODING, HEADER, FrameBatch, FrameError, decode, encode_binary, encode_json
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult
from service.sources.base import Inlet
from service.storage import Storage

with warnings.catch_warnings():  # Starlette warns at import that its TestClient will change HTTP client
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

NOW = 1_700_000_000.0
MIN_BINARY_FRAME = 40  # bytes of the smallest binary frame (5 float64 columns)
MIN_JSON_FRAME = 2  # a JSON array element needs at least a digit and a comma
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=-(10**40), max_value=10**40),
    st.none(), st.booleans(), st.text(max_size=3),
)
json_values = st.recursive(numbers, lambda inner: st.lists(inner, max_size=4), max_leaves=20)
columns = ("t", "V", "theta", "P", "Q", "f", "stat", "I", "phi")


def frame_bound(payload: bytes, encoding: str) -> int:
    """Most frames a message of this size could hold."""
    per = MIN_BINARY_FRAME if encoding == BINARY_ENCODING else MIN_JSON_FRAME
    return max(0, len(payload) - (HEADER.size if encoding == BINARY_ENCODING else 0)) // per + 1


def frames_in(payload: bytes, encoding: str) -> int:
    """What the ingest must count for this message: the decoded frames, or the error's count."""
    try:
        return len(decode(payload, encoding))
    except FrameError as exc:
        return exc.n


@st.composite
def valid_batches(draw) -> FrameBatch:
    n = draw(st.integers(0, 60))
    t0 = draw(st.sampled_from([NOW - 5.0, NOW - 3600.0, NOW + 3.0]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = t0 + np.arange(n) / 50.0
    return FrameBatch(t=t, V=1.0 + 0.01 * rng.standard_normal(n), theta=0.1 * rng.standard_normal(n),
                      P=0.8 + 0.01 * rng.standard_normal(n), Q=0.3 + 0.01 * rng.standard_normal(n),
                      f=50.0 + 0.01 * rng.standard_normal(n) if draw(st.booleans()) else None,
                      stat=np.zeros(n, np.uint16) if draw(st.booleans()) else None)


@st.composite
def mutated_binary(draw) -> bytes:
    payload = bytearray(encode_binary(draw(valid_batches()), t_ns=draw(st.booleans())))
    for _ in range(draw(st.integers(0, 4))):
        kind = draw(st.sampled_from(["flip", "truncate", "extend", "header", "float"]))
        if kind == "flip" and payload:
            i = draw(st.integers(0, len(payload) - 1))
            payload[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "truncate":
            del payload[draw(st.integers(0, len(payload))):]
        elif kind == "extend":
            payload += draw(st.binary(max_size=64))
        elif kind == "header" and len(payload) >= HEADER.size:
            n = draw(st.sampled_from([0, 1, 0xFFFFFFFF, 0x7FFFFFFF, draw(st.integers(0, 2**32 - 1))]))
            flags = draw(st.integers(0, 255))
            struct.pack_into("<BI", payload, 5, flags, 0)
            struct.pack_into("<I", payload, 8, n)
        elif kind == "float" and len(payload) >= HEADER.size + 8:
            i = draw(st.integers(HEADER.size, len(payload) - 8))
            value = draw(st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, -1e9, 1e30]))
            struct.pack_into("<d", payload, i, value)
    return bytes(payload)


@st.composite
def mutated_json(draw) -> bytes:
    obj = json.loads(encode_json(draw(valid_batches())))
    for _ in range(draw(st.integers(0, 4))):
        key = draw(st.sampled_from(columns))
        kind = draw(st.sampled_from(["replace", "drop", "element"]))
        if kind == "replace":
            obj[key] = draw(json_values)
        elif kind == "drop":
            obj.pop(key, None)
        elif isinstance(obj.get(key), list) and obj[key]:
            obj[key][draw(st.integers(0, len(obj[key]) - 1))] = draw(numbers)
    text = json.dumps(obj)
    if draw(st.booleans()):  # and some damage to the text itself
        cut = draw(st.integers(0, len(text)))
        text = text[:cut] + draw(st.text(max_size=8)) + text[cut + draw(st.integers(0, 4)):]
    return text.encode("utf-8", "surrogatepass")


messages = st.one_of(
    st.tuples(mutated_binary(), st.just(BINARY_ENCODING)),
    st.tuples(mutated_json(), st.sampled_from(["application/json", "text/json;charset=utf-8"])),
    st.tuples(st.binary(max_size=200), st.sampled_from([BINARY_ENCODING, "application/json", "text/plain", ""])),
)


@FUZZ
@given(messages)
def test_a_decoder_returns_equal_columns_or_a_bounded_frame_error(message):
    payload, encoding = message
    try:
        batch = decode(payload, encoding)
    except FrameError as exc:
        assert 0 <= exc.n <= frame_bound(payload, encoding)
        return
    n = len(batch)
    assert n <= frame_bound(payload, encoding)
    for col in (batch.t, batch.V, batch.theta, batch.P, batch.Q, batch.f, batch.stat):
        assert col is None or (col.ndim == 1 and col.shape[0] == n)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(["b1", "b2", "a/b", "*", "a/**", "", "x//y"]), messages), max_size=12),
       st.floats(-10.0, 10.0))
def test_the_inlet_counts_every_frame_once_and_never_raises(sequence, clock_skew):
    clock = ManualClock(NOW + clock_skew)
    store = BufferStore(10.0, 50.0, 1.0)
    inlet = Inlet(store, max_future_s=5.0, f0=50.0, clock=clock)
    sent = 0
    for bus, (payload, encoding) in sequence:
        sent += frames_in(payload, encoding)
        inlet.message(bus, payload, encoding)
        clock.advance(0.5)
    tot = store.totals()
    assert tot.messages == len(sequence)
    assert tot.frames_received == sent
    assert all(k > 0 for k in tot.frames_rejected.values())
    for bus in store.buses():
        buf = store.buffer(bus, create=False)
        held = buf.data[0, buf.start:buf.end]
        assert (np.diff(held) > 0).all() and np.isfinite(held).all() and (held > 0).all()


# --- REST --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def client(tmp_path_factory):
    from test_service_api import View

    tmp = tmp_path_factory.mktemp("fuzz-rest")
    cfg = settings_for(tmp, 7447, period_s=10.0, window_s=2.0, late_s=0.5)
    store = BufferStore(cfg.window_s, cfg.frame_rate, cfg.late_s)
    storage = Storage(cfg.storage_path)
    view = View(cfg, store, storage, LatestResults(), ServiceMetrics(store), cfg.period_s)
    storage.save_results([BusResult(bus="b1", period=1000.0, period_s=10.0, status="skipped", reason="gap",
                                    completed_at=1000.5)])
    with TestClient(create_app(view)) as c:
        yield c
    storage.close()


bus_text = st.text(st.characters(codec="utf-8"), max_size=140)
query_value = st.one_of(st.text(max_size=30), st.sampled_from(["nan", "inf", "-inf", "1e999", "-1e999",
                                                               "99999999999999999999999", "0", "-1"]))


@FUZZ
@given(bus_text, st.sampled_from(["parameters/latest", "parameters", "diagnosis/latest"]))
def test_rest_bus_paths_never_give_a_server_error(client, bus, tail):
    r = client.get(f"/buses/{quote(bus, safe='/')}/{tail}")
    assert r.status_code in (200, 404, 422), (bus, r.status_code, r.text)


@FUZZ
@given(st.dictionaries(st.sampled_from(["since", "until", "limit", "ok"]), query_value, max_size=4))
def test_rest_query_strings_never_give_a_server_error(client, params):
    for path in ("/buses/b1/parameters", "/buses/b1/parameters/latest", "/periods"):
        r = client.get(path, params=params)
        assert r.status_code in (200, 404, 422), (path, params, r.status_code, r.text)


finite_json = st.recursive(
    st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False, allow_infinity=False),
              st.integers(-(10**30), 10**30), st.text(max_size=5)),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=10,
)


@FUZZ
@given(st.one_of(finite_json, st.fixed_dictionaries({"period_s": finite_json})), st.booleans())
def test_rest_config_bodies_never_give_a_server_error(client, body, with_token):
    # Non-finite periods (NaN, 1e999) are issue 17's defect 2, fixed on the operations side.
    headers = {"Authorization": "Bearer op-secret"} if with_token else {}
    r = client.put("/config", content=json.dumps(body), headers={**headers, "Content-Type": "application/json"})
    assert r.status_code in ((200, 422) if with_token else (401, 422)), (body, r.status_code, r.text)
    if r.status_code == 200:  # put the period back for the next example
        client.put("/config", json={"period_s": 10.0}, headers=headers)
