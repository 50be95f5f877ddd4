"""The commands' modules; each exposes ``register(subparsers)``, and
``bearcat.cli.COMMANDS`` says which module holds which command."""
