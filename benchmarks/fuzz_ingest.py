"""Fuzz the ingest: mutated PMU messages on hostile bus names through the Inlet, then over real Zenoh.

Each message starts as a valid batch (binary in its four layouts, or JSON in seconds, nanoseconds or
current phasors) of a bus whose frames advance with a manual clock, then gets 0-3 mutations: bit flips,
truncation, trailing garbage, a forged header (n = 0xFFFFFFFF, random flags), special values written
into the columns (NaN, ±inf, 1e30, 0, -1e9, 4.8 s in the future, an hour behind), JSON tokens replaced
(huge integers, 1e999, null, strings, nested arrays, stat 70000), a wrong encoding.  Bus names include
wildcards (``*``, ``a/*/b``), empty chunks, names too long and a flood of one-off names beyond the bus
cap.  Idle eviction runs meanwhile.

Checked, exactly: no exception escapes the Inlet; messages sent = messages counted; frames sent =
frames buffered + frames rejected with a reason, where the frames of a message are what the codec finds
in it (the decoded batch, or the count an undecodable message is charged, itself checked to be no more
than its bytes hold).

    .venv/bin/python benchmarks/fuzz_ingest.py --messages 1000000 --zenoh-messages 100000
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import random
import struct
import sys
import time
import traceback

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.buffers import BufferStore  # noqa: E402
from service.clock import ManualClock  # noqa: E402
from service.frames import (  # noqa: E402
    BINARY_ENCODING,
    FLAG_CURRENT,
    HEADER,
    FrameBatch,
    FrameError,
    decode,
    encode_binary,
)
from service.sources.base import Inlet  # noqa: E402

FS = 50.0
START = 1_700_000_000.0
BUSES = 500
MAX_BUSES = 2_000  # small, so that the flood of one-off names reaches it
HOSTILE = ["*", "**", "a/*/b", "bus$*", "", "/lead", "trail/", "a//b", "x" * 200, "ctl\x01"]
SPECIALS = [float("nan"), float("inf"), float("-inf"), 1e30, 0.0, -1e9]
JSON_TOKENS = ["1e999", "-1e999", "1" + "0" * 30, "-" + "9" * 25, "null", '"x"', "[[1]]", "70000", "-1",
               "true", "{}", "1.5"]


class Fuzzer:
    """Makes mutated messages; ``rng`` seeds everything (a run is reproducible)."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        nrng = np.random.default_rng(seed)
        n = 50
        self.cols = {"V": 1 + 0.01 * nrng.standard_normal(n), "theta": 0.1 * nrng.standard_normal(n),
                     "P": 0.8 + 0.01 * nrng.standard_normal(n), "Q": 0.3 + 0.01 * nrng.standard_normal(n),
                     "f": 50 + 0.01 * nrng.standard_normal(n)}
        self.cursor: dict[str, float] = {}
        self.one_offs = 0
        self.steps = np.arange(1, n + 1) / FS
        self._templates: dict[tuple, bytes | str] = {}

    def bus(self) -> str:
        r = self.rng.random()
        if r < 0.03:
            return self.rng.choice(HOSTILE)
        if r < 0.08:
            self.one_offs += 1
            return f"junk/{self.one_offs}"
        return f"bus{self.rng.randrange(BUSES):04d}"

    def valid(self, bus: str, now: float) -> tuple[bytes, str]:
        rng = self.rng
        n = rng.choice((1, 10, 50, 50))
        t0 = max(self.cursor.get(bus, now - 1.0), now - 3.0)
        self.cursor[bus] = t0 + n / FS
        t = t0 + self.steps[:n]
        if rng.random() < 0.75:
            key = (n, rng.random() < 0.3, rng.random() < 0.3, rng.random() < 0.2, rng.random() < 0.1)
            data = bytearray(self._binary(*key))
            if key[3]:  # t as int64 ns
                np.frombuffer(data, "<i8", n, HEADER.size)[:] = np.round(t * 1e9).astype(np.int64)
            else:
                np.frombuffer(data, "<f8", n, HEADER.size)[:] = t
            return bytes(data), BINARY_ENCODING
        times = [int(x * 1e9) for x in t.tolist()] if rng.random() < 0.3 else t.tolist()
        return (f'{{"t":{json.dumps(times, separators=(",", ":"))},{self._json_rest(n, rng.random() < 0.3)}}}'
                .encode(), "application/json")

    def _binary(self, n: int, f: bool, stat: bool, t_ns: bool, current: bool) -> bytes:
        """A valid binary message template (times patched in per message); cached by layout."""
        key = (n, f, stat, t_ns, current)
        if key not in self._templates:
            c = self.cols
            batch = FrameBatch(t=START + self.steps[:n], V=c["V"][:n], theta=c["theta"][:n], P=c["P"][:n],
                               Q=c["Q"][:n], f=c["f"][:n] if f else None,
                               stat=np.zeros(n, np.uint16) if stat else None)
            payload = encode_binary(batch, t_ns=t_ns)
            if current:  # the current-phasor layout: same bytes, columns 4-5 read as I, phi
                payload = payload[:5] + bytes([payload[5] | FLAG_CURRENT]) + payload[6:]
            self._templates[key] = payload
        return self._templates[key]

    def _json_rest(self, n: int, stat: bool) -> str:
        """The JSON columns after ``t`` (cached)."""
        key = ("json", n, stat)
        if key not in self._templates:
            obj = {k: self.cols[k][:n].tolist() for k in ("V", "theta", "P", "Q")}
            if stat:
                obj["stat"] = [0] * n
            self._templates[key] = json.dumps(obj, separators=(",", ":"))[1:-1]
        return self._templates[key]

    def mutate(self, payload: bytes, encoding: str, now: float) -> tuple[bytes, str]:
        rng = self.rng
        data = bytearray(payload)
        for _ in range(rng.choice((0, 1, 1, 2, 3))):
            op = rng.randrange(7)
            if op == 0 and data:
                i = rng.randrange(len(data))
                data[i] ^= 1 << rng.randrange(8)
            elif op == 1:
                del data[rng.randrange(len(data) + 1):]
            elif op == 2:
                data += rng.randbytes(rng.randrange(1, 48))
            elif encoding == BINARY_ENCODING and len(data) >= HEADER.size:
                if op == 3:
                    struct.pack_into("<I", data, 8, rng.choice((0, 1, 0xFFFFFFFF, rng.getrandbits(32))))
                elif op == 4:
                    data[5] = rng.getrandbits(8)
                elif len(data) >= HEADER.size + 8:
                    value = rng.choice(SPECIALS + [now + 4.8, now - 3600.0])
                    struct.pack_into("<d", data, HEADER.size + 8 * rng.randrange((len(data) - HEADER.size) // 8), value)
            elif encoding != BINARY_ENCODING and data:
                text = data.decode("utf-8", "replace")
                key = rng.choice(('"t":[', '"V":[', '"P":[', '"stat":[', '"Q":['))
                i = text.find(key)
                if i >= 0:
                    j = i + len(key)
                    k = text.find(",", j)
                    text = text[:j] + rng.choice(JSON_TOKENS) + (text[k:] if k > 0 else "]}")
                elif op == 6:
                    text = text.replace('"theta"', '"thet"', 1)
                data = bytearray(text.encode())
        if rng.random() < 0.02:
            encoding = rng.choice(("text/plain", BINARY_ENCODING, "application/json", ""))
        return bytes(data), encoding


def frames_in(payload: bytes, encoding: str, max_bytes: int) -> int:
    """The frames the ingest must account for in one message (the oracle; see the module docstring)."""
    if len(payload) > max_bytes:
        return 0
    try:
        return len(decode(payload, encoding))
    except FrameError as exc:
        per = 40 if encoding.split(";")[0].strip().lower() == BINARY_ENCODING else 2
        if exc.n > len(payload) // per + 1:
            raise AssertionError(f"{exc.reason}: charged {exc.n} frames for {len(payload)} bytes") from None
        return exc.n


def in_process(n_messages: int, seed: int) -> bool:
    clock = ManualClock(START)
    store = BufferStore(10.0, FS, 2.0, max_buses=MAX_BUSES)
    inlet = Inlet(store, max_future_s=5.0, f0=50.0, clock=clock)
    fz = Fuzzer(seed)
    sent_frames = errors = 0
    oracle_s = 0.0
    step = 1.0 / BUSES  # each regular bus sends about one message per second
    start = time.perf_counter()
    for i in range(n_messages):
        now = clock.now()
        bus = fz.bus()
        payload, encoding = fz.mutate(*fz.valid(bus, now), now)
        o = time.perf_counter()
        sent_frames += frames_in(payload, encoding, inlet.max_message_bytes)
        oracle_s += time.perf_counter() - o
        try:
            inlet.message(bus, payload, encoding)
        except Exception:  # noqa: BLE001 - counted: the target is zero
            errors += 1
            if errors <= 5:
                traceback.print_exc()
        clock.advance(step)
        if i % 30_000 == 29_999:  # the scheduler's idle sweep, every minute of simulated time
            store.evict_idle(clock.now() - 30.0)
    elapsed = time.perf_counter() - start
    tot = store.totals()
    rejected = sum(tot.frames_rejected.values())
    ok = errors == 0 and tot.messages == n_messages and tot.frames_buffered + rejected == sent_frames
    print(f"in-process: {n_messages:,} mutated messages in {elapsed:.1f} s "
          f"({n_messages / (elapsed - oracle_s):,.0f} msg/s through the Inlet, oracle time excluded)")
    print(f"  uncaught exceptions {errors}; messages counted {tot.messages:,} of {n_messages:,}")
    print(f"  frames sent {sent_frames:,} = buffered {tot.frames_buffered:,} + rejected {rejected:,} "
          f"-> {'exact' if tot.frames_buffered + rejected == sent_frames else 'MISMATCH'}")
    print(f"  frames rejected by reason {dict(sorted(tot.frames_rejected.items()))}")
    print(f"  messages rejected by reason {dict(sorted(tot.messages_rejected.items()))}")
    print(f"  buses live {tot.buses:,} (cap {MAX_BUSES:,}), evicted {tot.buses_evicted:,}, "
          f"one-off names {fz.one_offs:,}")
    return ok


def publisher(port: int, n_messages: int, seed: int, ready, result, done) -> None:
    import zenoh

    from service.zenoh_config import zenoh_config

    session = zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{port}"], listen=[]))
    fz = Fuzzer(seed)
    ready.set()
    time.sleep(1.0)
    sent = frames = refused = 0
    encodings: dict[str, zenoh.Encoding] = {}
    # PMU time runs from 10 min ago at one message per regular bus per second (as in-process), so that
    # sending faster than real time neither runs into the receiver's future nor turns into duplicates.
    virtual0 = time.time() - 600.0
    for i in range(n_messages):
        now = virtual0 + i / BUSES
        bus = fz.bus()
        payload, encoding = fz.mutate(*fz.valid(bus, now), now)
        enc = encodings.get(encoding) or encodings.setdefault(encoding, zenoh.Encoding(encoding))
        try:
            session.put(f"aslm/pmu/{bus}", payload, encoding=enc, congestion_control=zenoh.CongestionControl.BLOCK)
        except Exception:  # noqa: BLE001 - Zenoh itself refuses some keys (empty chunks, '?', '#')
            refused += 1
            continue
        sent += 1
        frames += frames_in(payload, encoding, 1 << 20)
    result.put((sent, frames, refused))
    done.wait(600)  # closing earlier could drop what is still queued towards the receiver
    session.close()


def over_zenoh(n_messages: int, seed: int, port: int) -> bool:
    import zenoh

    from service.sources.zenoh import ZenohSource
    from service.zenoh_config import zenoh_config

    store = BufferStore(10.0, FS, 2.0, max_buses=MAX_BUSES)
    session = zenoh.open(zenoh_config("peer", listen=[f"tcp/127.0.0.1:{port}"], connect=[]))
    source = ZenohSource(session, "aslm")
    source.start(Inlet(store, max_future_s=5.0, f0=50.0))
    ctx = mp.get_context("spawn")
    ready, result, done = ctx.Event(), ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=publisher, args=(port, n_messages, seed, ready, result, done))
    start = time.perf_counter()
    proc.start()
    ready.wait(120)
    sent, frames, refused = result.get(timeout=3600)
    deadline = time.monotonic() + 120
    while store.totals().messages < sent and time.monotonic() < deadline:
        time.sleep(0.2)
    elapsed = time.perf_counter() - start
    done.set()
    proc.join(30)
    tot = store.totals()
    rejected = sum(tot.frames_rejected.values())
    ok = (source.internal_errors == 0 and tot.messages == sent and tot.frames_buffered + rejected == frames)
    print(f"zenoh: {sent:,} mutated messages received in {elapsed:.1f} s ({refused:,} keys refused by Zenoh's "
          f"own put); callback errors {source.internal_errors}; messages counted {tot.messages:,}")
    print(f"  frames sent {frames:,} = buffered {tot.frames_buffered:,} + rejected {rejected:,} "
          f"-> {'exact' if tot.frames_buffered + rejected == frames else 'MISMATCH'}; "
          f"bad_bus messages {tot.messages_rejected.get('bad_bus', 0):,}")
    print(f"  frames rejected by reason {dict(sorted(tot.frames_rejected.items()))}")
    source.close()
    session.close()
    return ok


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=1_000_000, help="mutated messages through the Inlet")
    ap.add_argument("--zenoh-messages", type=int, default=100_000, help="mutated messages over Zenoh (0: skip)")
    ap.add_argument("--seed", type=int, default=17)
    ap.add_argument("--port", type=int, default=17_717)
    args = ap.parse_args()
    ok = in_process(args.messages, args.seed)
    if args.zenoh_messages:
        ok = over_zenoh(args.zenoh_messages, args.seed + 1, args.port) and ok
    print("PASS" if ok else "FAIL")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
