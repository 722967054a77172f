"""Shared fixtures: the report's configs solved through the pipeline once per session."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def forward():
    """(setup, trim, linear, decoupled, design) of the bundled forward config."""
    from quadctl import config, pipeline
    from quadctl.setup import resolve

    setup = resolve(config.load("forward"))
    trim = pipeline.trim_of(setup)
    linear = pipeline.linear_of(setup, trim)
    dec = pipeline.decoupled_of(setup, linear)
    des = pipeline.design_of(setup, dec, linear)
    return setup, trim, linear, dec, des


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path_factory, monkeypatch):
    """Compiled steps go to one session-wide temporary cache, never the user's."""
    monkeypatch.setenv("QUADCTL_CACHE", str(tmp_path_factory.getbasetemp() / "qc-cache"))
