"""Every number quadctl writes for a bundled config is the number it wrote before (the stored
reference, see ``tests/_reference_runs.py``): a refactor that moves one fails here, naming it."""

from __future__ import annotations

import json

import pytest
from _reference_runs import CONFIGS, REFERENCE, differences, digest, run_folder


@pytest.fixture(scope="module")
def reference():
    return json.loads(REFERENCE.read_text())


@pytest.mark.compiler
@pytest.mark.parametrize("name", CONFIGS)
def test_run_folder_numbers_are_the_reference(name, reference, tmp_path):
    found = differences(reference[name], digest(run_folder(name, tmp_path)), name)
    assert not found, f"{len(found)} numbers moved:\n" + "\n".join(found[:40])


def test_the_comparison_sees_a_moved_number(reference):
    """The comparison is not blind: one gain moved by 1e-9 of itself, or one artifact gone, is found."""
    ref = reference["forward"]
    moved = json.loads(json.dumps(ref))
    before = ref["design.json"]["K_block"][1][4]
    moved["design.json"]["K_block"][1][4] = after = before * (1 + 1e-9)
    assert differences(ref, moved) == [f".design.json.K_block[1][4]: {before!r}, now {after!r} "
                                       f"(diff {abs(after - before):.3e})"]
    del moved["sim.npz"]
    assert ".sim.npz: missing" in differences(ref, moved)
