"""The dashboard (issue 6): server-side views and aggregation behind ``/dashboard``.

``app.dashboard.aggregate`` bins and thins arrays (pure numpy); ``app.dashboard.views``
builds the JSON of each view from the service context. The page itself lives in
``app/static/`` and is served by ``app.routes.dashboard``. See docs/dashboard.md.
"""

from app.dashboard.aggregate import MAX_BINS, MAX_SCATTER, histogram, shared_edges, thin_scatter

__all__ = ["MAX_BINS", "MAX_SCATTER", "histogram", "shared_edges", "thin_scatter"]
