"""The quadctl command line: typer commands over the library (nothing imports this package)."""
