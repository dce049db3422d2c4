"""The ``occmap`` subcommands, one module each.

Every module here has ``add_parser(subparsers)``, which adds the command and its options to the
``argparse`` subparsers of :func:`occmap.cli.main` and returns its parser, and ``run(args)``, which
does the work and returns the exit code. A module imports only ``argparse`` and the helpers of
this package at import time; the library parts it uses are imported inside ``run``, so building
the parser stays cheap and each command loads only the kernels it uses.

Options are checked when the command line is parsed (``_options``) and output names before any
data is read (``_outputs``); bad input raises :class:`occmap.errors.OccmapError`, which the CLI
prints as one line on stderr with exit code 2.
"""

#: The commands in the order ``occmap --help`` lists them; each names a module of this package.
NAMES = ("demo", "map2d", "map3d", "info", "convert", "export", "render", "view", "local", "localize", "warmup")
