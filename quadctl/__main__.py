"""``python -m quadctl``."""

from quadctl.cli.entry import main

main()
