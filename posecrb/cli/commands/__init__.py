"""One module per subcommand; each exposes ``command`` (a click command or group).

Shared options and helpers are in ``_common``. Commands format results and
raise library exceptions; ``posecrb.cli.main`` turns those into exit codes.
"""
