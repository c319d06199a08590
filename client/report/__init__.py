"""Replay reports: ``report.json``, the per-frame CSV, plots and an HTML index.

:func:`write_report` (:mod:`.html`) turns one replay (its summary from :func:`~walkstream.client.report.metrics.summarise`,
its :class:`~walkstream.client.report.metrics.FrameLog` and the link's bytes log) into a folder::

    report.json   the summary (JSON-safe: numpy types converted, NaN/inf -> null)
    frames.csv    one row per frame, the FrameLog columns
    bytes.csv     the link's (t, cumulative bytes) samples
    bytes.png     bytes downloaded over time (cumulative kB, and rate in kbit/s)
    quality.png   download and rewrite quality per frame over time (paper 001, Figure 1)
    fps.png       displayed frame rate over time, target and +-10 % band, floor-limited
                  frames marked, the uncounted first second shaded
    budget.png    polygon budget and triangles drawn over time
    phases.png    the frame loop's milliseconds per phase (with ``phases.csv``), when timed
    interior.png  an interior walk: visible cells, portals, triangles, culling ms, fog
    error.png     the image error against the ground truth: missing pixels by cause and,
                  on a city walk, the colour error (with ``truth.csv`` and the worst
                  compared frames, by missing pixels and by colour error, under
                  ``truth/``), with ``--truth-every``
    index.html    a self-contained page: headline table, every plot and snapshot
                  (relative links), the summary JSON

:func:`write_comparison` overlays several runs (with / without prefetch, meshes ...) for
the stream benchmark.  Every file is written to a temporary file in the same folder
and moved into place with :func:`os.replace`, so a reader never sees half a file and
writing over an earlier report replaces it file by file.  Long logs are drawn through a
min/max envelope of at most a few thousand points per line, so 15,000 frames plot as
fast as 1,500 and spikes still show.

The modules: :mod:`.metrics` (the per-frame log and every figure computed from it:
the one definition of frame rate, perfect frame and recovery), :mod:`.files`
(``report.json`` and the CSVs, written atomically), :mod:`.tables` (headline figures
as text), :mod:`.plots` (one function per figure), :mod:`.html` (the folder and its
index page), :mod:`.phases` (``phases.csv`` and ``phases.png``), :mod:`.truth` (the
``truth`` figures) with :mod:`.colour` (their colour figures) and :mod:`.colourview`
(the worst frame by colour error as pictures), :mod:`.link` (a walk's link figures), :mod:`.city`,
:mod:`.interior` and :mod:`.crossing` (each scene kind's figures of the summary).  A new plot is a function in :mod:`.plots`, a name in
:data:`PLOT_NAMES` (and in :data:`BASE_PLOT_NAMES` when every report holds it) and a
caption in :mod:`.html`.
"""

from walkstream.client.report.files import (
    BytesLog,
    json_safe,
    load_run,
    read_bytes_csv,
    read_frames_csv,
    write_bytes_csv,
    write_frames_csv,
    write_json,
)
from walkstream.client.report.framelog import FrameLog, FrameLogBuilder, displayed_fps
from walkstream.client.report.html import write_comparison, write_report
from walkstream.client.report.metrics import (
    Recovery,
    link_utilisation,
    recovery_frames,
    summarise,
    within_ratio,
    within_target_mask,
)
from walkstream.client.report.plots import BASE_PLOT_NAMES, PLOT_NAMES, SERIES_COLOURS
from walkstream.client.report.tables import format_comparison_table, format_headline, headline_rows

__all__ = [
    "FrameLog",
    "FrameLogBuilder",
    "Recovery",
    "displayed_fps",
    "link_utilisation",
    "within_target_mask",
    "within_ratio",
    "recovery_frames",
    "summarise",
    "write_report",
    "write_comparison",
    "BytesLog",
    "json_safe",
    "write_json",
    "write_frames_csv",
    "read_frames_csv",
    "write_bytes_csv",
    "read_bytes_csv",
    "load_run",
    "BASE_PLOT_NAMES",
    "PLOT_NAMES",
    "SERIES_COLOURS",
    "headline_rows",
    "format_headline",
    "format_comparison_table",
]
