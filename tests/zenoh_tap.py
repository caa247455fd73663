"""A Zenoh peer on 127.0.0.1 that collects what the bridges publish on ``aslm/pmu/**`` (for the bridge tests)."""

from __future__ import annotations

import numpy as np
from c37118_peers import free_port

from service.frames import decode_binary


class ZenohTap:
    """A Zenoh peer listening on a free port, collecting {prefix}/pmu/** batches."""

    def __init__(self) -> None:
        import zenoh

        from service.zenoh_config import zenoh_config

        self.port = free_port()
        self.session = zenoh.open(zenoh_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{self.port}"]))
        self.batches: list = []
        self.sub = self.session.declare_subscriber(
            "aslm/pmu/**", lambda s: self.batches.append((str(s.key_expr), decode_binary(s.payload.to_bytes()))))

    def columns(self, key: str | None = None) -> np.ndarray:
        """t, V, θ, P, Q of every batch received (of ``key`` only, if given), as rows."""
        return np.concatenate([np.stack([b.t, b.V, b.theta, b.P, b.Q]) for k, b in self.batches
                               if key is None or k == key], axis=1)

    def frames(self) -> int:
        """Frames received so far."""
        return sum(len(b) for _, b in self.batches)

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()
