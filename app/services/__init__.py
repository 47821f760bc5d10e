"""The service's use cases: what a route, a CLI command or a dashboard view asks for.

Routes (``app.routes``), the CLI (``app.cli``) and the dashboard's views are thin
wrappers over these modules; the modules build on ``app.context`` (what is held once),
``app.domain`` (the domain packages, typed), ``app.jobs`` and ``app.db``.

- ``app.services.store``       open the store: the embedded dataset and the default model
- ``app.services.datasets``    upload a dataset, its table and exposure, list, show
- ``app.services.models``      the one fit path (``fit_model``), fit on a stored dataset,
                               list, look up
- ``app.services.sampling``    sample and score (``POST /scenarios``, ``scengen sample``),
                               a model's unconstrained reference draws
- ``app.services.catalogues``  create, run, describe, list, page, export and delete
                               catalogues
- ``app.services.rates``       a region's P(A) with both intervals and its rates; two
                               models compared on one region
- ``app.services.risk``        score a concrete scenario (``POST /risk``, ``scengen risk``)

Import the module you need (``from app.services import catalogues``): this face loads
none of them, so a command that needs one use case does not load the others.
"""
