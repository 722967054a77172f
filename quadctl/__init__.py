"""quadctl: trim, linearize, decouple, check, design and simulate LQR controllers for quadcopters."""

__version__ = "0.1.0"
