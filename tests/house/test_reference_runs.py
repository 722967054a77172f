"""Every number quadctl writes for a bundled config is the number it wrote before (the stored
reference, see ``tests/_reference_runs.py``), on any CPU: a refactor that moves one fails here,
naming it; another BLAS kernel's rounding, within the number's conditioning, does not."""

from __future__ import annotations

import json

import pytest
from _reference_runs import ARGMAX_RTOL, CONFIGS, REFERENCE, compare, differences, digest, run_folder, tolerance


@pytest.fixture(scope="module")
def reference():
    return json.loads(REFERENCE.read_text())


@pytest.mark.compiler
@pytest.mark.parametrize("name", CONFIGS)
def test_run_folder_numbers_are_the_reference(name, reference, tmp_path):
    found = compare(reference[name], digest(run_folder(name, tmp_path)), name)
    assert not found, f"{len(found)} numbers moved:\n" + "\n".join(found[:40])


@pytest.mark.parametrize("name", CONFIGS)
def test_the_comparison_sees_a_moved_gain(name, reference):
    """Every config's tolerance, from its loop's conditioning, still sees a gain moved by 1e-9 of
    itself, or one artifact gone."""
    ref = reference[name]
    assert tolerance(ref) < 0.5e-9
    moved = json.loads(json.dumps(ref))
    K = ref["design.json"]["K_block"]
    row, col = max(((i, j) for i in range(len(K)) for j in range(len(K[i]))), key=lambda ij: abs(K[ij[0]][ij[1]]))
    before = ref["design.json"]["K_block"][row][col]
    moved["design.json"]["K_block"][row][col] = after = before * (1 + 1e-9)
    found = compare(ref, moved)
    assert found == [f".design.json.K_block[{row}][{col}]: {before!r}, now {after!r} "
                     f"(diff {abs(after - before):.3e}, tolerance {max(tolerance(ref) * abs(after), 1e-12):.1e})"]
    del moved["sim.npz"]
    assert ".sim.npz: missing" in compare(ref, moved)


def _eigen(pairs):
    return {"closed_loop_eigenvalues": pairs}


def test_eigenvalues_compare_as_a_multiset():
    """A solver's order is not a number: a reordered set is the same set; a conjugate pair
    swapped too; one eigenvalue moved beyond its tolerance is named."""
    ref = _eigen([[-1.0, 0.0], [-2.0, 3.0], [-2.0, -3.0], [-100.0, 0.0]])
    assert differences(ref, _eigen([[-100.0, 0.0], [-2.0, -3.0], [-1.0, 0.0], [-2.0, 3.0]])) == []
    moved = _eigen([[-100.0, 0.0], [-2.0, -3.0], [-1.0 + 1e-9, 0.0], [-2.0, 3.0]])
    (found,) = differences(ref, moved)
    assert found.startswith(".closed_loop_eigenvalues: eigenvalue -1+0j nearest -0.999999999+0j (diff 1.000e-09")


def test_a_peak_frequency_moves_within_its_conditioning_only():
    ref = {"disk_margin_freq": 219.58705986771565, "disk_margin": 0.5}
    assert differences(ref, {"disk_margin_freq": 219.58599235958349, "disk_margin": 0.5}) == []
    assert differences(ref, {"disk_margin_freq": 219.587 * (1 + 3 * ARGMAX_RTOL), "disk_margin": 0.5})
    assert differences(ref, {"disk_margin_freq": 219.58705986771565, "disk_margin": 0.5 + 1e-9})


def test_a_matrix_compares_to_its_largest_entry():
    """A Riccati solution's structural zeros hold round-off of its norm: another BLAS kernel gave
    -1.07e-12 where the reference has 6.4e-13 in a hover P whose largest entry is about 10. Those move
    within ``rtol`` of the largest entry; the largest entry moved by 1e-9 of itself does not."""
    ref = {"P": [[10.0, -1.0679816151081693e-12], [-1.0679816151081693e-12, 2.0]]}
    assert differences(ref, {"P": [[10.0, 6.365416410935803e-13], [6.365416410935803e-13, 2.0]]}, rtol=1e-12) == []
    assert differences(ref, {"P": [[10.0 * (1 + 1e-9), 0.0], [0.0, 2.0]]}, rtol=1e-12)
    assert differences(ref, {"P": [[10.0, 0.0], [0.0, 2.0 + 1e-9]]}, rtol=1e-12)


def test_singular_values_compare_to_the_largest():
    """Weyl: rounding ``E`` moves every singular value by at most ``||E|| ~ n eps sigma_max``."""
    ref = {"ctrb_singular_values": [1.5e8, 10.186437748852033]}
    assert differences(ref, {"ctrb_singular_values": [1.5e8, 10.18643774931379]}) == []
    assert differences(ref, {"ctrb_singular_values": [1.5e8, 10.2]})
