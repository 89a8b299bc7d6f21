"""mop: computer puppetry by demonstration.

The application package: takes (recordings), sessions, rendering, outputs and the CLI. It is the
only package that imports `capture`, `followers` and `characters` together."""

__version__ = "0.1.0"
