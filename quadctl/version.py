"""quadctl's version: what every artifact and exported file records, and the package's ``__version__``."""

__version__ = "0.1.0"
