"""``python -m quadctl``."""

from quadctl.cli.app import main

main()
