"""The harvest services: one package per service, the shared bus layer, the runtime and the CLI."""

__version__ = "0.1.0"
