"""The ``robofmu`` subcommands, one module each.

Each module declares its parser (``add_parser(subparsers)``) and runs the command (``main(args)``
returning the exit status), importing what it runs only inside ``main`` so that ``robofmu --help``
stays fast. Commands share option declarations through :mod:`robofmu.system.options` and usage
checks and output-folder rules through :mod:`robofmu.system.usage`; no command module imports
another. :mod:`robofmu.system.cli` assembles them and maps exceptions to exit statuses.
"""
