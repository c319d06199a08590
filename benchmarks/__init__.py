"""The benchmarks: every speed, size and quality figure the project reports.

Each module is one benchmark that ``walkstream bench ...`` runs and prints as a table
(the command line only parses options and prints); none is part of the product:

- :mod:`.rebuild`: rebuild throughput per LOD, parameter against geometry bytes;
- :mod:`.visibility`: PVS misses against a dense reference, against bake time (the
  settings compared in :mod:`.vissettings`, the scene in :mod:`.visinput`, the table
  and plot in :mod:`.visreport`);
- :mod:`.renderspeed`: cells per second of the visibility renderer;
- :mod:`.load`: simulated walkers against a real server;
- :mod:`.stream`: replays per link and mode (quality, bytes, overfetch);
- :mod:`.budget`: frame rate and polygon budget per device, with a cost step;
- :mod:`.controller`: the budget controller alone on the device cost models;
- :mod:`.lod`: image error against frame time, ACH against distance LODs;
- :mod:`.fill`: where the gl device's frame time goes, lighting per fragment vs per vertex;
- :mod:`.impostorsampling`: one impostor against its truth, alone, per view, bake sampling
  and texture filter (why the impostors' own error is what it is);
- :mod:`.city`: OpenStreetMap extracts, street cells against grid cells;
- :mod:`.fieldspeed`: how fast the dense visibility field renders, the bake's renderer
  against exact occlusion culling (:mod:`.fieldcull`) on the same points;
- :mod:`.clusters`: visibility lists clustered along the cell adjacency (m-LOMA)
  against the delta-coded records: bytes of the cell records and of the walks' traffic;
- :mod:`.interiors`: interiors per IFC model and generated size (cells, portals,
  triangles, bake time, bytes per cell);
- :mod:`.portals`: portal culling against frustum culling alone and drawing everything,
  culling cost in open halls, the office tour's replays.

Helpers of those, not commands of their own:

- :mod:`.visref`: the dense reference of :mod:`.visibility`, kept on disk between runs;
- :mod:`.fieldcull`: the field's points rendered with exact occlusion culling (tried,
  measured by :mod:`.fieldspeed`, not the bake's renderer: it does not pay on llvmpipe);
- :mod:`.cellcodec`: the cell-contents codec's versions side by side (a table of
  ``walkstream bench interiors``);
- :mod:`.portalwalk`: the first portal walk, the reference that :mod:`.portals` times
  and tests/test_portalwalk.py checks the faster walk against;
- :mod:`.cullcpu`: the culling's CPU time per frame (``walkstream bench portals
  --cull``), beside the culling of an earlier revision;
- :mod:`.trianglecost`: what testing the kept room parts' triangles saves and costs
  (``walkstream bench portals --triangles``).

Scripts, not commands (they time product code against itself, no scene to bake):

- :mod:`.ringrepair`: footprint cleaning of a generated city, the whole-array GEOS checks
  against one polygon at a time, and ``city_summary`` (``python -m
  walkstream.benchmarks.ringrepair [SIZE ...]``);
- :mod:`.reportplots`: a replay report's plots, axes placed by fixed margins against
  measured by ``tight_layout`` (``python -m walkstream.benchmarks.reportplots REPORT_DIR``).

A new benchmark is a module here with a ``run_...`` function and a ``format_...``
table, and a subcommand in :mod:`walkstream.cmd_bench`.  The ``run_...`` functions are
imported lazily.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "building_stats": "walkstream.benchmarks.rebuild",
    "visibility_benchmark": "walkstream.benchmarks.visibility",
    "run_render_speed": "walkstream.benchmarks.renderspeed",
    "run_server_bench": "walkstream.benchmarks.load",
    "run_stream_bench": "walkstream.benchmarks.stream",
    "run_budget_bench": "walkstream.benchmarks.budget",
    "run_controller_bench": "walkstream.benchmarks.controller",
    "run_lod_bench": "walkstream.benchmarks.lod",
    "run_fill_bench": "walkstream.benchmarks.fill",
    "run_city_bench": "walkstream.benchmarks.city",
    "run_sections_bench": "walkstream.benchmarks.sections",
    "run_field_speed": "walkstream.benchmarks.fieldspeed",
    "format_sections_table": "walkstream.benchmarks.sections",
    "plot_sections_trade": "walkstream.benchmarks.sections",
    "run_clusters_bench": "walkstream.benchmarks.clusters",
    "format_clusters_table": "walkstream.benchmarks.clusters",
    "plot_clusters": "walkstream.benchmarks.clusters",
    "run_ring_bench": "walkstream.benchmarks.ringrepair",
    "format_ring_table": "walkstream.benchmarks.ringrepair",
    "run_plots_bench": "walkstream.benchmarks.reportplots",
    "run_pvs_misses": "walkstream.benchmarks.pvsmisses",
    "format_pvs_misses": "walkstream.benchmarks.pvsmisses",
    "format_plots_table": "walkstream.benchmarks.reportplots",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
