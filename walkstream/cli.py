"""The ``walkstream`` command: where server, client and shared pieces are wired together.

Each subcommand lives in a ``cmd_*`` module of this package (``cmd_build``: generate,
buildings, grammar; ``cmd_bake``: bake, inspect, serve; ``cmd_replay``; ``cmd_path``;
``cmd_bench``; ``cmd_demo``) and imports what it needs lazily so ``walkstream --help``
stays fast.  Errors a user can cause (``WalkstreamError``, unreadable files) end as
one line on stderr and exit status 2; nothing else is caught, so a bug still shows
its traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

from walkstream.shared.errors import WalkstreamError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    from walkstream.cmd_bake import add_bake_parsers
    from walkstream.cmd_bench import add_bench_parser
    from walkstream.cmd_build import add_build_parsers
    from walkstream.cmd_demo import add_demo_parser
    from walkstream.cmd_path import add_path_parser
    from walkstream.cmd_replay import add_replay_parser

    p = argparse.ArgumentParser(
        prog="walkstream",
        description=(
            "Interactive walkthroughs of large 3D scenes over slow links: procedural "
            "cities and real footprints, L-system buildings at three levels of detail."
        ),
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_demo_parser(sub)
    add_bake_parsers(sub)
    add_replay_parser(sub)
    add_path_parser(sub)
    add_build_parsers(sub)
    add_bench_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``walkstream`` console command."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except WalkstreamError as exc:
        print(f"walkstream: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"walkstream: error: {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("walkstream: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (``walkstream inspect db | head``): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())
