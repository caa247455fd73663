"""Sources of PMU frames, by the names the ``sources`` setting uses.

A new source is one module in this package (a class with ``name``, ``start(inlet)`` and ``close()``, see
:mod:`service.sources.base`, and a ``build(ctx)`` factory taking a :class:`service.context.Context`)
plus one line in :data:`SOURCES`.
"""

SOURCES: dict[str, str] = {
    "zenoh": "service.sources.zenoh:build",
    "c37118": "service.sources.c37118:build",
    "sttp": "service.sources.sttp:build",
    "zenoh-sharded": "service.sources.sharded:build",
}
"""name → ``module:factory`` (imported only when a service starts that source; see service.registry)."""
