"""Static, offline HTML report of the pipeline's Zarr stores.

Public API::

    index = reports.build_report(["out/quick.zarr"], "out/report")   # -> Path of index.html

The command line is ``python -m reports build [STORE ...] --out out/report/``. The site is
``index.html`` plus ``plotly.min.js`` (written once, referenced relatively), so it opens from
disk with no network, and ``audit.json``. The page opens with the reproduction audit (every
quantitative claim of the paper's results, ``reports/claims.toml``, with our value from the
stores and a verdict), then one section per figure of the paper in the paper's order
(``reports/figures.toml``), then the studies; figures are drawn when they scroll into view.
Shipped scenes without a store are listed as not yet run; a store of another format is refused
(:class:`StoreRefused`).
"""

from ._build import build_report, default_stores
from ._read import SUPPORTED_FORMAT, SceneStore, StoreRefused, open_scene_store

__all__ = ["build_report", "default_stores", "open_scene_store", "SceneStore", "StoreRefused", "SUPPORTED_FORMAT"]
