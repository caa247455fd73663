"""Sinks of results, diagnoses and periods, by the names the ``sinks`` setting uses.

A new sink is one module in this package (a class with the methods of :class:`service.sinks.base.Sink`
and a ``build(ctx)`` factory taking a :class:`service.context.Context`) plus one line in :data:`SINKS`.
"""

SINKS: dict[str, str] = {
    "storage": "service.sinks.storage:build",
    "zenoh": "service.sinks.zenoh:build",
    "records": "service.sinks.records:build",
    "bus_metrics": "service.sinks.bus_metrics:build",
    "tracking": "service.sinks.tracking:build",
}
"""name → ``module:factory`` (imported only when a service uses that sink; see service.registry)."""
