"""walkstream: interactive walkthroughs of large 3D scenes over slow links.

The distribution installs one import name.  Its packages: :mod:`walkstream.shared`
(used by both sides), :mod:`walkstream.server`, :mod:`walkstream.client`,
:mod:`walkstream.benchmarks`; the modules of this folder are the command line
(:mod:`walkstream.cli` and its ``cmd_*`` modules), where the pieces are wired together.
"""

from walkstream.shared.exports import lazy_exports

_EXPORTS = {
    "main": "walkstream.cli",
    "build_parser": "walkstream.cli",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
