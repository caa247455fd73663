"""One place that turns settings into a :class:`zenoh.Config`."""

from __future__ import annotations

import json

import zenoh


def zenoh_config(mode: str = "peer", connect: list[str] | None = None, listen: list[str] | None = None,
                 multicast_scouting: bool = False, config_file: str | None = None) -> zenoh.Config:
    """Build a Zenoh config.

    Parameters
    ----------
    mode : {"peer", "client", "router"}
    connect, listen : list of str
        Endpoints such as ``tcp/127.0.0.1:7447`` (``tls/...`` with certificates from ``config_file``).
    multicast_scouting : bool
        Off by default: explicit endpoints, nothing leaves the configured interfaces.
    config_file : str, optional
        JSON5 Zenoh config loaded first (TLS, access control, ...); the arguments above override it.
    """
    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if connect is not None:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast_scouting)))
    return conf


def from_settings(settings) -> zenoh.Config:
    """Zenoh config of a :class:`service.settings.ServiceSettings`."""
    return zenoh_config(
        settings.zenoh_mode, settings.zenoh_connect, settings.zenoh_listen, settings.zenoh_multicast_scouting,
        str(settings.zenoh_config_file) if settings.zenoh_config_file else None,
    )
